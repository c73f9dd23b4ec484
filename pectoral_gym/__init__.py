"""pectoral-gym: a robotic fish with two rowing pectoral fins, as models and Gymnasium environments.

Importing the package registers ``PectoralFish-Full-v0`` and ``PectoralFish-Averaged-v0``.
"""

from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.models import AveragedModel, FishModel, FullModel
from pectoral_gym.model.params import FinBeat, FishParams
from pectoral_gym.registration import register_envs

__version__ = "0.1.0"

register_envs()

__all__ = ["AveragedModel", "FinBeat", "FishModel", "FishParams", "FullModel", "ScalingFunctions", "__version__"]
