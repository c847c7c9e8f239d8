"""The follower: the friction-wheel guidewire drive, its parameters, sensors and scenarios."""
