"""myoexo: knee-exoskeleton digital twin with spastic reflexes on MyoSuite.

Importing the package registers the gymnasium / MyoSuite env ids
``MyoExoKnee-v0`` .. ``MyoExoKnee-v3`` and ``MyoExoKneeRandom-v0``.
"""

from __future__ import annotations

__version__ = "0.1.0"
