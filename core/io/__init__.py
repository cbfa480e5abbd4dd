"""File formats beside the numerics, as ``colour.io``: CGATS/``.ti3`` (:mod:`.cgats`),
raw decoding (:mod:`.raw`), the capture session store (:mod:`.session`) and the
measurement exports with rawtoaces JSON (:mod:`.export`).

Every reader validates through ``core.limits``; the numerics in ``core`` take arrays
and spectra, and the modules here turn files into them and back.
"""
