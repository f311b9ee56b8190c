# The public face of exubio for type checkers and IDEs (the module itself loads these lazily).
from exubio.api import angle_status as angle_status
from exubio.api import angles as angles
from exubio.api import assess as assess
from exubio.api import calibrate as calibrate
from exubio.api import load_model as load_model
from exubio.api import load_protocol as load_protocol
from exubio.api import moments as moments
from exubio.api import load_study as load_study
from exubio.api import read_trial as read_trial
from exubio.api import reconstruct as reconstruct
from exubio.api import rhythm as rhythm
from exubio.api import simulate as simulate
from exubio.api import to_dataframe as to_dataframe
from exubio.api import write_results as write_results
from exubio.errors import ExubioError as ExubioError
from exubio.errors import InputError as InputError
from exubio.errors import ModelError as ModelError
from exubio.errors import ProtocolError as ProtocolError
from exubio.errors import ReconstructionError as ReconstructionError
from exubio.types import Model as Model
from exubio.types import Protocol as Protocol
from exubio.types import Reconstruction as Reconstruction
from exubio.types import Trajectories as Trajectories

__version__: str
__all__: list[str]
