"""The autopilot: flight modes, altitude hold, scheduled attitude control, control allocation."""
