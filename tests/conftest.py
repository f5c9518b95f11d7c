import math

import numpy as np
import pytest

from onboard.geometry import attitude_from_yaw_pitch_roll


@pytest.fixture
def R_north() -> np.ndarray:
    """Level vehicle facing +y (north)."""
    return attitude_from_yaw_pitch_roll(math.pi / 2)
