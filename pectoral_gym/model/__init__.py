"""The fish model, with no Gymnasium.

Parameters, the tank, fin strokes, body dynamics, the cycle-averaged model,
the scaling functions K, the batched integrators, the model specs and the CasADi twin of the averaged model.
"""
