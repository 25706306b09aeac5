"""An 8-bit grey PNG from rows of pixel values, for the floor-plan scripts
beside it (office.py, loop.py): the standard library only, so they run on
any Python 3."""
import struct
import zlib


def gray_png(img):
    """The PNG of `img`, a list of rows (top first) of values 0-255."""
    rows, cols = len(img), len(img[0])
    raw = b"".join(b"\x00" + bytes(row) for row in img)

    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    return (b"\x89PNG\r\n\x1a\n"
            + chunk(b"IHDR", struct.pack(">IIBBBBB", cols, rows, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 9))
            + chunk(b"IEND", b""))
