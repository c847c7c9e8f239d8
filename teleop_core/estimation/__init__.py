"""The force estimator: eq. 1 physics, the GRU residual and the EKF that fuses them."""
