"""Eye adaptation (auto exposure): scene metering, temporal adaptation and the middle-grey operator.

The stage follows the eye-adaptation method of source document 002 (meter the frame by
downsampling it to a fixed power-of-two size and averaging 2x2 blocks down to 1x1, move an
adapted luminance towards the metered one over time, then expose the frame so that the adapted
luminance lands on middle grey), with two corrections to that document:

* **Adaptation direction.** The document computes ``avg + (prev - avg) * (1 - pow(0.98, 30 dt))``,
  which returns the *new* average at ``dt = 0`` and drifts back towards the *previous* value as
  time passes. torchgrade moves from the previous value towards the new one:
  ``adapted + (metered - adapted) * (1 - exp(-dt * speed))``, so ``dt = 0`` changes nothing and a
  long ``dt`` settles on the metered value. (The document's rate ``pow(0.98, 30 dt)`` is
  ``exp(-dt * 30 ln(1 / 0.98))``, i.e. ``speed ≈ 0.606`` per second.)
* **Colour scaling.** The document returns ``Lcompressed * rgb``; a colour is brought to a new
  luminance by multiplying it by ``Lcompressed / L``. torchgrade writes that ratio without
  dividing by ``L`` (``scaled / L = middle_grey / adapted``), so it is exact and safe at ``L = 0``.

Two operators are offered. ``"exposure"`` (the default) returns the scene-referred image
``rgb * middle_grey / adapted`` so that bloom, grading and tone mapping can follow, as in the
library's pipeline ``AutoExposure -> Bloom -> ColorGrade -> ToneMap``. ``"reinhard"`` is the
document's operator, Reinhard et al. 2002 "Photographic Tone Reproduction", Eq. 4 with the
white point ``max_luminance``: it returns a display-referred image in which luminance
``max_luminance`` maps to 1 (brighter luminances exceed 1 and are not clipped here).

Pixels go through the library's non-finite policy (:func:`torchgrade.base.images.sanitize`) before
metering and before the operator, and outputs are bounded to ±65504, so one NaN or Inf pixel
changes neither the metered value nor any other pixel. float16/bfloat16 images are computed in
float32 and returned in their own dtype; the adapted luminance is float32 for them.
"""

from .adaptation import OPERATORS, adapt_luminance, auto_exposure, compensation_at, exposure_operator
from .layer import AutoExposure
from .metering import (HISTOGRAM_BINS, METERING_MASKS, METERING_MODES, area_resize, halving_average, histogram_band_average,
                       meter_luminance, metering_weights)

__all__ = [
    "AutoExposure",
    "auto_exposure",
    "meter_luminance",
    "adapt_luminance",
    "exposure_operator",
    "area_resize",
    "halving_average",
    "METERING_MODES",
    "METERING_MASKS",
    "HISTOGRAM_BINS",
    "metering_weights",
    "histogram_band_average",
    "compensation_at",
    "OPERATORS",
]
