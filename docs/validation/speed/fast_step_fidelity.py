"""The fidelity benchmark and the validation report with the averaged model's ``fast_step`` on.

``python docs/validation/speed/fast_step_fidelity.py OUT_DIR [SET ...] [--no-validate]`` (sets default:
``dev report``):

* ``pectoral-scaling fidelity --set SET`` with the candidate ``averaged`` (``spec.AVERAGED``, both corrections,
  the shipped K) replaced by ``AVERAGED.replace(fast_step=True)``: ``OUT_DIR/fidelity_SET.md`` and ``.json``,
  to compare with ``docs/validation/fidelity/fidelity_SET.md`` (the same sets, the default step);
* ``pectoral-scaling validate`` (Table 4, single-fin, forward sweep and two-fin steady states), whose
  averaged model is ``make_model("averaged")``, i.e. ``spec.AVERAGED``: here rebound to the fast spec in the
  modules that read it, ``OUT_DIR/validate/report.md``, to compare with ``docs/validation/report.md``.
"""

import sys
from pathlib import Path

from pectoral_gym.model import spec as spec_module
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.scaling.validation import comparison, fidelity, validate

out = Path(sys.argv[1])
sets = [name for name in sys.argv[2:] if name != "--no-validate"] or ["dev", "report"]
fast = spec_module.AVERAGED.replace(fast_step=True)
scaling = ScalingFunctions.load(None)
for seed_set in sets:
    fidelity.fidelity(scaling, seed_set, out, plots=False, progress=False, source="shipped (fast_step on)",
                      candidate="averaged", spec=fast)
    print(f"wrote {out / f'fidelity_{seed_set}.md'}", flush=True)
if "--no-validate" not in sys.argv:
    spec_module.AVERAGED = fast  # make_model("averaged") reads the module's AVERAGED
    comparison.AVERAGED = fast
    validate.validate(scaling, out_dir=out / "validate", plots=False, progress=False, source="shipped (fast_step on)")
    print(f"wrote {out / 'validate' / 'report.md'}")
