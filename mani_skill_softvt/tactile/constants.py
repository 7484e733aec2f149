"""GelSight Mini sensor constants (SI units unless noted; pixels for image quantities)."""

# Output image: 320 x 240 (W x H), half the Mini's 640 x 480 calibration resolution.
IMAGE_WIDTH = 320
IMAGE_HEIGHT = 240
CALIB_WIDTH = 640  # resolution of the taxim calibration data (polynomial coordinates, background)
CALIB_HEIGHT = 480
# taxim's GelSight Mini calibration: 0.0295 mm per pixel at 640 x 480, so 0.059 mm at 320 x 240:
# a field of view of 18.9 x 14.2 mm (the Mini's datasheet says about 18.6 x 14.3 mm).
PIXEL_SIZE = 2 * 0.0295e-3  # m per output pixel

# Elastomer: the object's penetration is clamped to what the gel can take.
GEL_THICKNESS = 2.0e-3  # m; a Mini's gel is ~2-3 mm thick
MAX_PENETRATION = 1.5e-3  # m; beyond this the gel bottoms out on its acrylic backing
CONTACT_THRESHOLD = 1e-5  # m of penetration that counts as contact (sub-pixel noise floor)

# Gel smoothing: the membrane spreads an indentation over ~0.3-1 mm around the contact
# (Taxim's pyramid of Gaussians); sigmas in output pixels, coarse to fine.
GEL_PYRAMID_SIGMAS = (8.0, 4.0, 2.0)
GEL_FINAL_SIGMA = 1.0

# Lookup table of the photometric model (taxim's polycalib): bins over gradient magnitude
# [0, pi/2] and direction [-pi, pi].
NUM_BINS = 125

# Markers: uniform 11 x 9 grid (columns x rows) with a margin of half a spacing.
MARKER_COLS = 11
MARKER_ROWS = 9
MARKER_RADIUS = 3.0  # px at 320 x 240 (the Mini's printed dots are ~0.35 mm)
MARKER_COLOR = (30, 30, 30)
# FOTS-style marker motion: dilation gain on the smoothed depth slope, and the reach of shear
# and twist outside the contact patch (exponential decay length).
DILATION_GAIN = 6.0  # px of marker motion per unit slope of the (pixel-unit) smoothed depth
DILATION_SIGMA = 6.0  # px: smoothing of the depth before taking its slope
SHEAR_DECAY = 12.0  # px

# Sensor rate (the control rate: one frame per control step).
FRAME_RATE = 20
