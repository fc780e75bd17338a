"""talus: app (see DESIGN.md section 2)."""
