"""A benchmark and validation harness for time integrators.

Import packages: `harness` (framework), `problems` (catalogue), `implementations` (steppers).
"""

__version__ = "0.1.0"
