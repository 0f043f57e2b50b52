"""float64 constants for the kernels: a bare literal in a Warp kernel is float32."""

from __future__ import annotations

import warp as wp

F64_ZERO = wp.constant(wp.float64(0.0))
F64_HALF = wp.constant(wp.float64(0.5))
F64_ONE = wp.constant(wp.float64(1.0))
F64_TWO = wp.constant(wp.float64(2.0))
F64_THREE = wp.constant(wp.float64(3.0))
