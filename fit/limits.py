"""Resource limits of everything the fitter reads or is asked to compute.

Rule: an input of at most 10 MB -- a file or a command-line value -- may not make ``rbrdf-fit``
(or the renderer, which reads rational and CDF files through :mod:`fit`) use more than about
2 GB of memory or run for more than about a minute before it either succeeds or stops with a
one-line error. Every size that a file or a flag can set is therefore bounded here, by an
explicit constant, checked *before* anything of that size is allocated; the message names the
file (or flag), the key, the value and the constant. docs/robustness.md lists them with the
measurements behind them.

The limits are far above what the project's own files and defaults use (the factor is given
for each); raising one is a code change, on purpose.
"""
from __future__ import annotations

# --- files -------------------------------------------------------------------------------------
#: Largest JSON file (``rbrdf-rational`` coefficients, ``rbrdf-cdf`` tables) read, in bytes.
#: A default CDF file is 2.7 MB; the largest table :data:`MAX_CDF_CELLS` allows is ~11 MB.
MAX_JSON_BYTES = 16 << 20
#: Most arrays and objects (``[`` and ``{``, counted in the text before parsing) of a JSON
#: file: Python spends ~60-150 bytes and noticeable time on each (measured: 64 MB of ``[],``
#: took 3.25 GB and 72 s to parse). The largest CDF table has n_v x n_t <= 65536 rows.
MAX_JSON_CONTAINERS = 1 << 18
#: Largest RGL ``.bsdf`` tensor file read, in bytes (the shared RGB files are 0.66 MB).
MAX_RGL_FILE_BYTES = 64 << 20
#: Largest projected-BRDF ``.npz`` read, in bytes (rbrdf-fit writes ~0.5 MB), and the largest
#: uncompressed size of one of its arrays (the largest holds 90 x 90 x 3 float64 = 194 kB).
MAX_NPZ_BYTES = 16 << 20
MAX_NPZ_MEMBER_BYTES = 4 << 20
#: Deepest nesting of a JSON document (objects and arrays); the files need 6.
MAX_JSON_DEPTH = 64
#: Most entries (files and folders) a walk of an input folder or a ``**`` pattern looks at
#: (``rbrdf-fit batch``; the shared data folder holds < 100): a walk of ``/`` is refused, not waited on.
MAX_WALK_ENTRIES = 200_000

# --- RGL tensor files ----------------------------------------------------------------------------
#: Largest number of elements of all floating-point fields of an RGL file together (converted
#: to float64 and copied a few times by the interpolants; the shared files hold 1.6e5).
MAX_RGL_ELEMENTS = 1 << 23
#: Largest table side (``vndf``, ``luminance``, ``rgb``, ``ndf``, ``sigma`` rows and columns;
#: the shared files use 32 and 128) and number of ``theta_i`` slices (they use 8).
MAX_RGL_TABLE_SIDE = 1024
MAX_RGL_THETA_I = 256
#: Largest magnitude of a value in a floating-point field of an RGL file (the shared files:
#: rgb <= 31, ndf <= 1.7e4) and smallest ``sigma`` (they: >= 0.018); beyond, a value is absurd.
MAX_RGL_FIELD_ABS = 1e9
MIN_RGL_SIGMA = 1e-6

# --- BRDF values ---------------------------------------------------------------------------------
#: Largest BRDF value (1/sr) accepted from a measured file. MERL and RGL data stay below ~1e4;
#: larger values are corrupt data and would overflow the projection's variances.
MAX_BRDF_VALUE = 1e7

# --- rational coefficient files ------------------------------------------------------------------
#: Input variables of one rational function (BRDFs: 2; the CDF maps: 2 and 3).
MAX_RATIONAL_VARIABLES = 3
#: Largest exponent of one variable in a numerator or denominator term (the fitter's
#: --max-degree allows 20; the renderer unrolls the Chebyshev recurrences up to it).
MAX_RATIONAL_EXPONENT = 24
#: Most terms of one numerator or denominator (degree 20 in 2 variables has 231).
MAX_RATIONAL_TERMS = 512
#: Largest tensor Bernstein form of a denominator, prod(degree_v + 1), i.e. the array the Q > 0
#: certificate subdivides (2 variables of degree 24: 625).
MAX_BERNSTEIN_COEFFICIENTS = 4096
#: Most coefficients of one file, all pieces and functions together (shipped fits: < 300;
#: the renderer compiles every term into its kernels).
MAX_FILE_COEFFICIENTS = 8192
#: Most pieces of one split, and nesting of splits (the fitter writes <= 3 pieces, depth 2).
MAX_PIECES = 32
MAX_SPLIT_DEPTH = 4
#: Sub-boxes the Q > 0 re-certification of one function may examine on load (the fitter's
#: certificates need <= 10), and the Bernstein coefficients examined for a whole file.
MAX_CERTIFY_BOXES = 4096
MAX_CERTIFY_WORK = 50_000_000

# --- sampling tables (CDF files and ``rbrdf-fit cdf`` flags) -----------------------------------
#: Largest theta_v rows, theta_l and |phi_l| cells of a table (defaults 32, 64, 64), and the
#: most cells n_v * n_t * n_p (the defaults use 131072; the file is ~21 bytes per cell).
MAX_CDF_ROWS = 128
MAX_CDF_THETA_CELLS = 512
MAX_CDF_PHI_CELLS = 512
MAX_CDF_CELLS = 1 << 19
#: Most pieces of the pieces layout per map (defaults n_mu = 64, n_u <= 64), and the most
#: phi pieces of a whole file, n_v * n_mu * n_u (the defaults use 65536).
MAX_CDF_PIECES = 1024
MAX_CDF_PHI_PIECES = 1 << 21

# --- fitter flags --------------------------------------------------------------------------------
#: ``--max-degree`` and ``--max-den-degree`` (defaults 12 and 6): each degree pair is an LP
#: whose columns grow with the square of the degree; the search tries up to ~25 pairs.
MAX_FIT_DEGREE = 20
MAX_FIT_DEN_DEGREE = 12
#: ``--tol``: a relative tolerance in [1e-4, 0.5] (default 0.05).
MIN_TOLERANCE = 1e-4
MAX_TOLERANCE = 0.5
#: ``--floor-frac`` (default 1): the absolute floor in units of tol * A_Y / pi.
MAX_FLOOR_FRAC = 100.0
#: ``--core-theta-d`` in degrees: the guaranteed core (default auto = 60, 50 or 40).
MIN_CORE_THETA_D_DEG = 5.0
#: ``--refinements`` (global layout, default 1) and ``--time-limit`` in seconds (default 180).
MAX_REFINEMENTS = 10
MAX_TIME_LIMIT_S = 86400.0

# --- memory --------------------------------------------------------------------------------------
#: Estimated peak memory (bytes) any single step may ask for; estimates are checked before
#: the allocation (:func:`check_memory`).
MEMORY_BUDGET_BYTES = 1536 << 20


def check_memory(estimate_bytes: float, what: str) -> None:
    """Raise ``ValueError`` naming ``what`` when ``estimate_bytes`` exceeds
    :data:`MEMORY_BUDGET_BYTES` (callers turn it into a one-line error naming their file or flag)."""
    if estimate_bytes > MEMORY_BUDGET_BYTES:
        raise ValueError(f"{what} would need about {estimate_bytes / 2**30:.3g} GiB of memory, above the "
                         f"limit {MEMORY_BUDGET_BYTES / 2**30:.3g} GiB (fit.limits.MEMORY_BUDGET_BYTES)")
