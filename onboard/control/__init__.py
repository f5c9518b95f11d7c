"""Pure control maths: guidance laws, FOV-holding yaw, geometric attitude loop."""
