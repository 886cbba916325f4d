"""The column layout of the sub-contacts' ``sc_grid`` (scenes with zoned blocks), shared by
the grid store, the gridpoint sub-contacts and the field declarations."""

from __future__ import annotations

# columns of the sub-contacts' ``sc_grid`` (scenes with zoned blocks only): the block-local
# gridpoint of the zoned side the sub-contact sits at (-1: none), then for side A and side B
# the block-local gridpoints of the surface triangle it lies on and their weights (a rigid
# side's are unused). Block-local, so that they travel with the contact between ranks and
# into checkpoints; :meth:`GridStore.record` turns them into the flat indices the kernel reads.
GRID_WIDTH = 13
GNODE = 0
TRI = (slice(1, 4), slice(7, 10))
W = (slice(4, 7), slice(10, 13))
