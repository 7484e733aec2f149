"""GelSight Mini sensor constants (SI units unless noted; image quantities in output pixels).

The photometric calibration (colour polynomial table, background frame) comes from the
installed ``taxim`` package's GelSight Mini folder; the numbers here describe the sensor's
geometry, the gel model and the marker model around it.
"""

from __future__ import annotations

from ..provenance import TACTILE_MODEL_VERSION, TACTILE_SOFT_MODEL_VERSION

# ---------------------------------------------------------------- image / optics geometry
# Output image 320 x 240 (W x H): half of the Mini's 640 x 480 calibration resolution, small
# enough for a policy observation and an exact 2x downsample of taxim's calibration frame.
IMAGE_WIDTH = 320
IMAGE_HEIGHT = 240
# Resolution and pixel pitch of taxim's GelSight Mini calibration (params.json): the colour
# polynomial is evaluated in these pixel coordinates.
CALIB_WIDTH = 640
CALIB_HEIGHT = 480
CALIB_PIXEL_SIZE = 0.0295e-3  # m per calibration pixel
# Square output pixels: the calibration pitch x 2 = 0.059 mm. Field of view = pixel size x
# resolution = 18.88 x 14.16 mm, i.e. the Mini's datasheet ~18.6 x 14.3 mm within 2 %; we keep the
# calibrated square pitch rather than the datasheet's rounded numbers (which would give
# non-square pixels and slopes the colour table was not fitted for).
PIXEL_SIZE = CALIB_PIXEL_SIZE * CALIB_WIDTH / IMAGE_WIDTH
FOV_WIDTH = IMAGE_WIDTH * PIXEL_SIZE  # m, along image columns (pad x)
FOV_HEIGHT = IMAGE_HEIGHT * PIXEL_SIZE  # m, along image rows (pad y)

# ---------------------------------------------------------------- elastomer
# The Mini's gel is ~2 mm thick: an object can push its surface in by at most that much before
# reaching the rigid acrylic backing, so penetration is clamped to [0, GEL_THICKNESS].
GEL_THICKNESS = 2.0e-3  # m
# Gel compliance. GelSight elastomers are soft, clear silicones of about Shore A 5 (Yuan, Dong &
# Adelson, "GelSight", Sensors 2017); Gent's Shore-to-modulus relation puts that at E ~ 0.3 MPa.
# Silicone rubber is nearly incompressible, nu ~ 0.47-0.49. A thin layer bonded to rigid acrylic
# and pressed over an area wider than it is thick cannot bulge sideways, so it resists with its
# confined modulus: Johnson's elastic foundation (Contact Mechanics, sec. 5.9),
# K = (1 - nu) E / ((1 + nu)(1 - 2 nu) h) (tactile.gel). K diverges as nu -> 0.5, which a finite
# contact never reaches; we take nu = 0.47, the low end, giving K = 6.0 E / h = 9.0e8 Pa/m.
# Order-of-magnitude values: no one has published a Mini's gel modulus.
GEL_MODULUS = 0.3e6  # Pa
GEL_POISSON = 0.47
# The gel is solved on a grid of 2 x 2 output pixels (0.118 mm): finer than any FEM feature and
# than the gel's own spreading (>= 1 output px), 4x fewer pixels; the image is upsampled after.
GEL_GRID_DOWNSAMPLE = 2
# 10 um of penetration counts as contact: below the gel's visible response and above
# floating-point noise of a mesh resting on the gel plane.
CONTACT_THRESHOLD = 1e-5  # m
# Surfaces more than this far *behind* the gel plane are on the far side of the finger (an
# object wrapping around it), not pressing the gel: the rasteriser ignores them.
BEHIND_PAD_CULL = 10e-3  # m

# Gel spreading (Taxim): the membrane conforms to the object where it is pressed hardest and
# relaxes smoothly around it. Taxim's GelSight Mini params.json gives Gaussian pyramid sigmas
# relative to the image width (deform_pyramid_sigma_rel); times 320 px they are:
GEL_PYRAMID_SIGMAS = (15.25, 7.75, 4.0, 1.75, 1.0, 0.55)  # px, coarse to fine
GEL_FINAL_SIGMA = 1.0  # px; taxim's deform_final_sigma_rel x 320: the gel's fine blur
# Only pixels pressed deeper than this fraction of the maximum penetration are pinned to the
# object during the pyramid (taxim's contact_scale): the contact rim is left to relax, which
# gives the soft edge of real GelSight contacts.
GEL_CONTACT_SCALE = 0.4
# Blur kernels are truncated at this many sigmas (weights beyond are < 1 %), and blurs with a
# sigma above GEL_COARSE_SIGMA run on a downsampled image (~10x cheaper; the rendered image
# matches exact blurs within one grey level on > 99.8 % of pixels).
GEL_KERNEL_SIGMAS = 3.0
GEL_COARSE_SIGMA = 3.0  # px

# Colour lookup (taxim polycalib.npz): 125 x 125 bins over the surface slope angle [0, pi/2]
# and the gradient direction [-pi, pi], each bin an RGB quadratic in the pixel coordinates.
NUM_BINS = 125

# ---------------------------------------------------------------- markers
# Uniform 11 x 9 grid (columns x rows) with half-spacing margins, like the Mini's printed dots.
MARKER_COLS = 11
MARKER_ROWS = 9
MARKER_RADIUS = 3.0  # px at 320 x 240: the printed dots are ~0.35 mm across (~6 px)
MARKER_COLOR = (30, 30, 30)  # RGB: dots read nearly black through the gel
MARKER_DRAW_SHIFT = 4  # cv2 fixed-point bits: dots drawn at 1/16 px so sub-pixel motion shows
# Dilation: the pressed volume flows out through the gel layer (tactile.markers.gel_flow). Its
# only physical constants are the gel's thickness and the parabolic profile across it (no slip
# on the acrylic, a free surface: the surface moves 1.5x the layer's mean). The indentation is
# summed over cells of FLOW_POOL x FLOW_POOL pixels (on the gel grid: 0.47 mm, a quarter of the
# markers' 1.7 mm spacing) before the marker sums.
FLOW_SURFACE_FACTOR = 1.5
FLOW_POOL = 4  # px of the grid the markers are computed on
# Shear and twist are carried fully under the contact and decay as exp(-distance / decay)
# outside it: the gel is bonded to the acrylic, so it drags only a margin around the patch.
SHEAR_DECAY = 12.0  # px (~0.7 mm)

# The tactile model's version and its history: mani_skill_softvt/provenance/.
MODEL_VERSION = TACTILE_MODEL_VERSION
SOFT_MODEL_VERSION = TACTILE_SOFT_MODEL_VERSION


def model_version(deformable: bool) -> int:
    """The tactile model version of frames of deformable (FEM) or rigid-twin objects."""
    return SOFT_MODEL_VERSION if deformable else MODEL_VERSION
