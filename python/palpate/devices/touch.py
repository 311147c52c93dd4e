"""The Geomagic Touch adapter's former module name (``palpate device touch`` is now ``palpate
device geomagic``, so that ``touch`` names only the scripted touches of ``palpate touch``):
:mod:`palpate.devices.geomagic_touch`."""
from .geomagic_touch import TouchAdapter

__all__ = ["TouchAdapter"]
