"""Calibration of the model from run logs: the uncertain FishParams fields of one's own robot.

``python -m pectoral_gym.scaling calibrate --logs RUN [RUN ...] --out robot.json`` (:mod:`.cli`);
the library: :func:`~pectoral_gym.scaling.calibration.fit.calibrate`. Modules: :mod:`.replay` (the
logged fins, replayed once by the firmware's rules, driving many candidate fish), :mod:`.windows`
(shooting windows and their starting states), :mod:`.fit` (robust least squares),
:mod:`.identifiability` (standard errors, what the logs cannot tell apart), :mod:`.heldout` (the
open-loop check), :mod:`.report` (JSON, Markdown, the plot), :mod:`.synth` (logs with a known truth),
:mod:`.benchmark` (the calibration's figures against its targets). See docs/calibration.md.
"""
