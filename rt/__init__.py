"""talus real-time side: robot model, twin, hardware backends, loop, supervisor.

Everything in this package is Qt-free (Qt lives only in ``app/``).
"""

import numpy as _np

# Messages quote values with ``{value!r}``; numpy 2 spells a scalar ``np.float64(0.05)``,
# which a clinician should never read. Scalars print as plain numbers again (arrays are
# unchanged). One setting for every message rather than a float() at each of them.
_np.set_printoptions(legacy="1.25")
