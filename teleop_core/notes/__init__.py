"""The NOTES simulator's 2-DOF haptic device (seed 001): model, characterisation, task."""
