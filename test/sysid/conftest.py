"""Single-threaded BLAS: the solves are small and the machine is shared."""

import os

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
