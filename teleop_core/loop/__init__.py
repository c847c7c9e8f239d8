"""The bilateral teleoperation loop: dial, follower, estimator and the link between them."""
