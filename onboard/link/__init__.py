"""MAVLink: the one adapter that speaks it and converts PX4's NED/FRD frames to our ENU/FLU,
the onboard parameter table, and the telemetry layout shared with the ground station."""
