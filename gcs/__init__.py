"""Ground-station library and CLI speaking MAVLink to the autopilot."""
