"""Friction: the coefficients of each contact and Coulomb friction."""
