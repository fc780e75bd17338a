"""talus: calibration (see DESIGN.md section 2)."""
