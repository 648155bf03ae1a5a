"""SESS-GAN generator: token maps, scenarios, the single-shot tokenized GAN (TOAD-GAN pyramid),
environment metrics and the generator node.
"""

__version__ = '0.1.0'
