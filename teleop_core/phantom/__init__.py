"""The simulated vascular phantom: aortic arch with its three branches (the LCCA task)."""
