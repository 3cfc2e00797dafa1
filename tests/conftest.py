import jax
import pytest

import hertzchain

jax.config.update("jax_enable_x64", True)


@pytest.fixture(scope="session")
def paper_setup():
    """The paper's chain: 21 steel beads, R = 13 mm, identical striker at 0.3 m/s, steel wall."""
    return hertzchain.ChainSetup()
