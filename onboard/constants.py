"""Physical constants, declared once and free of heavy imports (the scenario parser uses them
while ``groundstation --help`` must stay light)."""

GRAVITY_M_S2 = 9.81  # standard gravity used throughout (m/s^2)

# PX4 custom modes: main mode in bits 16-23, sub mode (AUTO) in bits 24-31
PX4_MAIN_POSCTL = 3
PX4_MAIN_AUTO = 4
PX4_MAIN_OFFBOARD = 6
PX4_SUB_AUTO_LOITER = 3
