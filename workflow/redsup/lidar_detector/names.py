"""Names ``plan`` and ``tables`` share (no imports), below both so that neither imports the other for a name."""

LIFTING = "lifting:"          # prefix of the ch. 6 runs a table row reads
