"""The onboard runtime: the interception loop on a real (or SITL) vehicle over MAVLink."""
