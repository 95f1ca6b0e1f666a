"""The arm's control systems: the action -> joint targets and gains, the impedance torque
law, the contact-primitive executor and where a push aims, the energy meter."""
