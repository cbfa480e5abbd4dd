"""TuneSpec application icons (SVG, PNG 16-512 px, Windows ICO).

Made by ``packaging/make_icons.py``; read through :mod:`importlib.resources`, e.g.
``resources.files("tunespec.resources.icons") / "tunespec.png"``. Licence: Apache-2.0
(this project).
"""
