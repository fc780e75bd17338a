"""talus: patients (see DESIGN.md section 2)."""
