"""Vision: a downward camera's pixels -> the deck marker's pose -> a relative measurement of the
deck from the vehicle. Pure computation on images (numpy, OpenCV): no socket, no clock, no global.
The frames and the models: docs/vision.md."""
