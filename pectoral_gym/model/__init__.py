"""The fish model, with no Gymnasium.

Parameters, the tank, fin strokes, body dynamics, the cycle-averaged model,
the scaling functions K, the batched integrators, the model specs and the CasADi twin of the averaged model;
the robot's servo limits (:mod:`.servo`) and fin rules (:mod:`.finrules`), which the envs, the robot's firmware,
the PC's replay of its fins (:mod:`.finreplay`), the backup shield and the calibration all run.
"""
