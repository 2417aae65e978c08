"""The simulated downward camera: frames rendered from the true poses of the vehicle and the deck,
with the sensor's noise, motion blur and dropouts (docs/vision.md)."""
