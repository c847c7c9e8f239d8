"""The NOTES simulator's 2-DOF haptic device ([notes]): model, characterisation, task."""
