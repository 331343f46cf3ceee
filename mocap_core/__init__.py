"""Pure algorithms of the solver: no sockets, no printing, no global state (docs/design.md, "How the code reads")."""
import os

# LLVM's -O2 for the numba kernels, not its default -O3: a first compile takes about a fifth less, and the kernels
# run as fast (docs/benchmarks.md). Set before numba is imported; a NUMBA_OPT of the user's own wins.
os.environ.setdefault("NUMBA_OPT", "2")
