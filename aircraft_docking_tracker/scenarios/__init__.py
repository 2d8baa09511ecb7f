"""Scenario bags: synthetic docking and UAV scenes with ground truth, and real datasets converted to bags."""
