"""The systematic table's deferred form: cells now, variances added later."""

from __future__ import annotations

import numpy as np

from tunespec.core.image_planes import SystematicTable


def test_cells_then_add_to_equals_the_lookup_at_once() -> None:
    rng = np.random.default_rng(5)
    table = SystematicTable(rng.uniform(0, 4, (10, 10, 10)),
                            rng.uniform(0, 1e-4, (10, 10, 10)), 7)  # fmt: skip
    lab = np.stack([rng.uniform(-5, 105, 500), rng.uniform(-120, 120, 500),
                    rng.uniform(-120, 120, 500)])  # fmt: skip
    unc = rng.uniform(0, 2, (500, 2)).astype(np.float32)
    add_l, add_rms = table.lookup(lab)
    at_once = np.sqrt(unc.astype(np.float64) ** 2 + np.stack([add_l, add_rms], axis=1))
    later = table.add_to(unc, SystematicTable.cells(lab))
    assert later.dtype == np.float32
    np.testing.assert_array_equal(later, at_once.astype(np.float32))
    assert float(np.min(later - unc)) >= 0.0 and float(np.max(later - unc)) > 0.1
