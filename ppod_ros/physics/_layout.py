"""Index layout of the flat float64 arrays that carry parameters into the compiled kernels.

Numba kernels take plain arrays; these module-level integers are compile-time constants there.
Keeping them in one place is what lets the Python side (``field.py``, ``dynamics.py``) and the
kernels agree without passing dozens of arguments.
"""

# ---- status codes (also the FieldResult reason codes) -------------------------------------------
OK = 0
CONTACT_LOST = 1
FRICTIONAL_SINGULARITY = 2
NOT_CONVERGED = 3
STEP_LIMIT = 4
STARTS_DISAGREE = 5

# ---- modes ---------------------------------------------------------------------------------------
SLIDE = 0
STICK = 1

# ---- point part parameters P (per configuration) ------------------------------------------------
PP_MU, PP_MUS, PP_X, PP_Y, PP_EVOLVE, PP_CANSTICK, PP_VSCALE = 0, 1, 2, 3, 4, 5, 6
PP_KAPPA = 7      # relative speeds below this are "just leaving" or "about to stick" (m/s)
PP_KAPPA_DEPART = 8  # a slip that has just left zero slides along -a_h up to this speed (m/s)
PP_CAPTURE_M = 9  # a slip about to stick is captured early while the position error stays below this (m)
PP_LAG_MAX = 10   # largest slow-manifold lag of a slip leaving zero (rad; 0: slide along -a_h)
PP_SIZE = 11

# ---- rigid part parameters P (per configuration) ------------------------------------------------
RP_MASS = 0
RP_I = 1          # 9 values, body-frame inertia, row-major
RP_R = 10         # 9 values, contact i at RP_R + 3 i (x, y, z)
RP_MU = 19        # 3
RP_MUS = 22       # 3
RP_EPS = 25       # regularisation velocity of the Coulomb law (m/s)
RP_X, RP_Y, RP_TH = 26, 27, 28
RP_EVOLVE = 29
RP_CANSTICK = 30
RP_VSCALE = 31    # velocity scale (m/s) for tolerances
RP_WSCALE = 32    # yaw-rate scale (rad/s) for tolerances
RP_DET0 = 33      # determinant of the frictionless contact system (sign reference)
RP_ZTOL = 34      # contact speeds below this are zero: a contact there slides along d_i (m/s)
RP_SIZE = 36

# ---- aux (mode and sliding-direction memory), per part -------------------------------------------
AX_MODE, AX_DX, AX_DY = 0, 1, 2
AX_READY = 3      # full dynamics: the mode has been derived for the current chunk
AX_BAND = 4       # rigid: 1 while contact i's speed is inside the regularisation band (3 values)
AX_RD = 7         # rigid: sliding direction of contact i at the last event (x, y per contact: 6 values)
AX_DEPART = 13    # point: 1 from a departure from w = 0 until |w| exceeds PP_KAPPA_DEPART
AX_SIZE = 16

# ---- work array W offsets -----------------------------------------------------------------------
W_U = 0           # plate acceleration (6)
W_V = 6           # plate velocity (6)
W_IW = 12         # world inertia (9)
W_RX = 21         # rho_x of the contacts (3)
W_RY = 24         # rho_y (3)
W_H = 27          # h (1)
W_M = 28          # 4x4 system (16)
W_B = 44          # right-hand side / solution (4)
W_N = 48          # normal forces (3)
W_E = 51          # contact sliding velocities / directions, x then y per contact (6)
W_S = 57          # scratch 6-vector
W_SIZE = 64

# ---- solver settings vector S --------------------------------------------------------------------
S_RTOL = 0
S_ATOL_V = 1        # m/s
S_ATOL_W = 2        # rad/s
S_FP_RTOL = 3       # fixed-point tolerance, relative to the velocity scale
S_FP_ATOL_V = 4
S_FP_ATOL_W = 5
S_MAX_PERIODS = 6
S_MAX_STEPS = 7     # per period
S_ZERO_RTOL = 8     # |w| below this (relative to the velocity scale) is a zero of the relative velocity
S_DEPTH = 9         # Anderson depth (0: plain fixed-point iteration)
S_CAPTURE = 10      # rigid: contact speeds below capture * eps trigger the sticking test
S_NSCAN = 11        # samples per period and harmonic for scans (root brackets, minima)
S_CLOSED_FORM = 12  # 1: closed-form solver where the plate motion at the point is collinear
S_WARM = 13         # 1: start from the neighbouring configuration's limit cycle
S_ERRKIND = 14      # 0: embedded pair, 1: DOP853's combined estimate
S_EXPONENT = 15     # step-size exponent -1/(q+1)
S_SKIP_STICK = 16   # 1: skip sticking logic where sticking is provably impossible
S_CHUNK = 17        # configurations per parallel work item
S_STARTS = 18       # rigid: number of initial twists compared
S_MIN_STEPS = 19    # steps per period and harmonic at least (events hide in longer steps)
S_LONG = 20         # 1: long chunks (>= CHUNK_LARGE): cubic extrapolation, the neighbour's rate prior
# Step-logic constants of _advance (EVENT_ERR_MAX, KAPPA_PER_STEP_TOL, KAPPA_DEPART_PER_STEP_TOL,
# ZERO_PER_RTOL, LAG_MAX_RAD), passed in S by SolverSettings.vector so that a benchmark can compare values
# without recompiling the kernels.
S_EVENT_ERR_MAX = 21  # a trial step with a larger error norm is shrunk without looking for events
S_KAPPA = 22        # point: PP_KAPPA in velocity step tolerances
S_KAPPA_DEPART = 23  # point: PP_KAPPA_DEPART in velocity step tolerances
S_ZERO_PER_RTOL = 24  # zero tolerance: this many rtol times the velocity scale (plus zero_velocity_rtol)
S_LAG_MAX = 25     # point: PP_LAG_MAX (rad)
S_SIZE = 26
