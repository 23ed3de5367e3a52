# Single source of the version: packaging reads it, and the C core is compiled with it so a stale
# build is caught at import (servobus.core._lib).
__version__ = "0.1.0"
