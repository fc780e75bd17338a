"""State estimation from the encoders: slider velocity and acceleration."""
