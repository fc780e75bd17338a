"""talus: reports (see DESIGN.md section 2)."""
