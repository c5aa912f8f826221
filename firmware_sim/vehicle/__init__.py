"""The nonlinear 6-DOF simulated vehicle: rigid body, rotors, aerodynamics, actuators, faults."""
