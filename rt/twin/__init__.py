"""The digital twin: physics of the robot, its sensors and environments (DESIGN section 7)."""
