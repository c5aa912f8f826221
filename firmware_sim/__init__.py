"""Flight software and simulated vehicle: ``autopilot`` (the controller side) and ``vehicle``
(the nonlinear 6-DOF plant). Neither imports the other: only sensor data and actuator commands
cross between them (passive FTC)."""
