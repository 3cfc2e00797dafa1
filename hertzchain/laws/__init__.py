"""Contact and dissipation laws as types.

A chain's contacts follow one contact law (`Hertz`, `PowerLaw`, `Thornton`,
`JacksonGreen`: subclasses of `AbstractContactLaw`) and any number of dissipation laws
(`Viscoelastic`, `Dashpot`, ...: subclasses of `AbstractDissipation`), given to
`hertzchain.ChainSetup` as `contact_law=` and `dissipation=`. Every kernel evaluates the
same methods; `registry` is the one table from a law type to its native counterpart.
"""

from . import registry as registry
from .contact_law import AbstractContactLaw as AbstractContactLaw
from .contact_law import ContactConstants as ContactConstants
from .dissipation import AbstractDissipation as AbstractDissipation
from .dissipation import Dashpot as Dashpot
from .dissipation import VelocitySquared as VelocitySquared
from .dissipation import Viscoelastic as Viscoelastic
from .dissipation import is_damped as is_damped
from .dissipation import total_force as total_force
from .elastic import Hertz as Hertz
from .elastic import PowerLaw as PowerLaw
from .plastic import JacksonGreen as JacksonGreen
from .plastic import Thornton as Thornton
