"""Drivers for the thesis rig's cards (PCL-833, PCI-1720) and the camera."""
