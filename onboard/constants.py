"""Physical constants, declared once and free of heavy imports (the scenario parser uses them
while ``groundstation --help`` must stay light)."""

GRAVITY_M_S2 = 9.81  # standard gravity used throughout (m/s^2)
