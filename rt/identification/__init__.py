"""Dynamic parameter identification (DESIGN §7): excitation, estimation, a description file."""
