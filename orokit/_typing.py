"""Type aliases shared across orokit."""
from __future__ import annotations

import os
from typing import Union

import numpy as np
from numpy.typing import NDArray

ArrayF = NDArray[np.floating]
ArrayI = NDArray[np.integer]
PathLike = Union[str, "os.PathLike[str]"]
SeedLike = Union[int, np.random.Generator, None]
