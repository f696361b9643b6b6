"""The viser web viewer: renders any method's checkpoint as the user moves the camera.

Last in the data flow (it may import everything, nothing imports it). Pure parts — camera
conversion, adaptive resolution, image colouring — are separate modules so they test without a
browser; :mod:`.server` wires them to viser.
"""
