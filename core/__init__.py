"""TuneSpec numerical core: spectra, forward model, calibration, estimation, colorimetry.

Pure numpy/scipy (plus colour-science, rawpy and OpenCV for file formats and geometry);
nothing here imports Qt or talks to a device.
"""
