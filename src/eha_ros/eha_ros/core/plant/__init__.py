"""Nonlinear EHA plant core (thesis ch. 3) and its linear models (eq. 3.24, 3.35, 3.41, 4.35)."""
from .model import EhaPlant, Measurement, Truth
from .parameters import PLANT_SCHEMA, PlantParams

__all__ = ['EhaPlant', 'Measurement', 'Truth', 'PLANT_SCHEMA', 'PlantParams']
