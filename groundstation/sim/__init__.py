"""The built-in simulator: multicopter, targets, wind, camera; it drives ``onboard``'s loop."""
