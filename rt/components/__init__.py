"""The real-time blocks of the position loop (sensor → estimate → model → control → drive)."""
