"""SESS-GAN evolver: GAN population, genetic operators, fitness, campaigns, failure bags, replay
and reports.
"""

__version__ = '0.1.0'
