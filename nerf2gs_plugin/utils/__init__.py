"""The ground floor: maths, file and config helpers and the C++ extension loader that every layer
above uses. Nothing here imports any other module of the package (tests/test_import_layers.py)."""
