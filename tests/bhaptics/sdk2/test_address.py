"""Where SDK2 is served: port 15882 on the ``--bhaptics`` host by default, moved by
``--bhaptics-sdk2``, a loopback address only."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from phantomtouch.service.settings import Settings


def test_sdk2_follows_the_sdk1_host_on_the_players_port() -> None:
    assert Settings().bhaptics_sdk2_address is None
    assert Settings(bhaptics_listen="127.0.0.1:15881").bhaptics_sdk2_address == (
        "127.0.0.1",
        15882,
    )
    moved = Settings(bhaptics_listen="127.0.0.1:15881", bhaptics_sdk2_listen="[::1]:25882")
    assert moved.bhaptics_sdk2_address == ("::1", 25882)


@pytest.mark.parametrize("listen", ["0.0.0.0:15882", "192.168.1.20:15882", "127.0.0.1", "x:0"])
def test_sdk2_listens_on_loopback_only(listen: str) -> None:
    with pytest.raises(ValidationError, match="bhaptics_sdk2_listen"):
        Settings(bhaptics_sdk2_listen=listen)
