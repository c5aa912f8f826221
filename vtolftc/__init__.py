"""vtol-ftc command line and the runners that wire an autopilot to a vehicle."""
