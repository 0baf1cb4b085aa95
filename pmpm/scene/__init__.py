"""Scene parsing: the TOML file read once, validated and frozen into dataclasses (config), the
tables that declare every key (tables), bodies turned into particle positions (bodies) and the
initial particle state of each rank (setup_particles)."""
