"""State estimation: the delayed Kalman filter for the target's image position."""
