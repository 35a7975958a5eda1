"""The virtual body (seed eq. 9-13): formation state, rotations, templates, kinematics, geometry."""
