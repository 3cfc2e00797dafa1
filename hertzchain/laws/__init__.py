"""Contact and dissipation laws as types.

A chain's contacts follow one contact law (`Hertz`, `PowerLaw`, `Thornton`,
`JacksonGreen`, and a law in series with a layer: `SeriesCompliance`, `RoughContact`;
subclasses of `AbstractContactLaw`) and any number of dissipation laws
(`Viscoelastic`, `Dashpot`, `VelocitySquared`, `HuntCrossley`: subclasses of `AbstractDissipation`), given to
`hertzchain.ChainSetup` as `contact_law=` and `dissipation=`; a driven chain's beads may
also sit on supports with micro-slip friction (`IwanSupport`). Every kernel evaluates the
same methods; `registry` is the one table from a law type to its native counterpart.
"""

from . import registry as registry
from .contact_law import AbstractContactLaw as AbstractContactLaw
from .contact_law import ContactConstants as ContactConstants
from .dissipation import AbstractDissipation as AbstractDissipation
from .dissipation import Dashpot as Dashpot
from .dissipation import HuntCrossley as HuntCrossley
from .dissipation import VelocitySquared as VelocitySquared
from .dissipation import Viscoelastic as Viscoelastic
from .dissipation import is_damped as is_damped
from .dissipation import total_force as total_force
from .elastic import Hertz as Hertz
from .elastic import PowerLaw as PowerLaw
from .plastic import JacksonGreen as JacksonGreen
from .plastic import Thornton as Thornton
from .rough import RoughContact as RoughContact
from .series import AbstractInSeries as AbstractInSeries
from .series import SeriesCompliance as SeriesCompliance
from .support_friction import IwanSupport as IwanSupport
from .registry import contact_law_from_keywords as contact_law_from_keywords
