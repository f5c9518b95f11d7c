"""Peregrine onboard: the interception loop that runs on the vehicle's companion computer.

Pure control maths (guidance, FOV holding, attitude loop), the delayed Kalman filter, the
detector and the closed loop that ties them together. Frames: world ENU, body FLU, camera
OpenCV (see DESIGN.md §2). This package never imports ``groundstation``.
"""

__version__ = "0.1.0"
