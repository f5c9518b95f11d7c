"""Software in the loop: the simulator as a PX4-like vehicle on a MAVLink link, with a camera
stream the onboard process opens as ``sitl://HOST:PORT``."""
