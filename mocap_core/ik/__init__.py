"""Inverse kinematics: constraints (thesis 3.3), four solvers (3.5) and their chain type."""
