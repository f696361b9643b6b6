"""City blocks: a large capture split into overlapping blocks by camera position on the ground
plane (VastGaussian / CityGaussian style), each block an ordinary dataset trained as an
independent run on any scheduler, and the block runs merged back into one run by cell.

``cells``: the grid of cells on the ground plane; ``partition``: the block datasets and
``partition.json``; ``reframe``: Gaussians from one run's normalised frame to another's;
``merge``: the merged run folder.
"""
