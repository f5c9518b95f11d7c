"""Pure control maths: guidance laws, FOV-holding yaw, geometric attitude loop."""

# The names of guidance.GUIDANCE_LAWS, importable without numpy (the command line's --help).
GUIDANCE_LAW_NAMES = ("png", "pg", "ibvs")
