"""A browser page that shows a picture and a panel of text beside it (viser): `so101 cameras --align`'s
overlay, always."""

from __future__ import annotations

import contextlib
import io
from typing import Any

import numpy as np
import numpy.typing as npt

RgbImage = npt.NDArray[np.uint8]


class PicturePage:
    """A viser page on host:port with a picture and what it means. `port` taken, viser takes the next free
    one: `address` says which."""

    def __init__(self, host: str, port: int, picture: RgbImage):
        import logging

        import viser

        from so101.web.settings import page_address

        logging.getLogger("websockets.server").setLevel(logging.CRITICAL)  # a probe's closed connection is no error
        with contextlib.redirect_stdout(io.StringIO()):  # viser's banner: the address is said in one line instead
            self.server: Any = viser.ViserServer(host=host, port=port, verbose=False)
        self.server.gui.configure_theme(control_width="large", show_share_button=False)
        self._text = self.server.gui.add_markdown("")
        self._picture = self.server.gui.add_image(picture, label="overlay", format="jpeg", jpeg_quality=85)
        self.address = page_address(host, int(self.server.get_port()))

    def show(self, picture: RgbImage, text: str) -> None:
        with self.server.atomic():
            self._picture.image = picture
            if text != self._text.content:
                self._text.content = text

    def close(self) -> None:
        server, self.server = self.server, None
        if server is not None:
            with contextlib.redirect_stdout(io.StringIO()):  # "(viser) Server stopped"
                server.stop()
