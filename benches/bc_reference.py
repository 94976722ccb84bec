"""rgbcx (through pip's `quicktex`) beside cirrus, every block decoded with the D3D
specification's float palette (endpoints r/31, g/63, b/31 or e/255, entries interpolated in
float, as a GPU decodes them):

  python bc_reference.py bc1 FOLDER...   each FOLDER a baked material with mra.png (the packed
                                         surface) and mra.ktx2 (cirrus's BC1): PSNR of both
  python bc_reference.py bc4 PBR_ROOT    every <set>/normal (X, Y) and <set>/ao under PBR_ROOT,
                                         every 37th block as the corpus test samples them: PSNR
                                         of rgbcx's BC4 (the corpus test prints cirrus's, the
                                         optimum's and ISPC's on the same blocks)
  python bc_reference.py bc7-visible PNG [CUTOFF]
                                         PNG a baked alpha-tested surface (a billboard cloud's
                                         albedo.png, an atlas's atlas.png) with cirrus's BC7
                                         beside it (the .ktx2 of the same name): the PSNR of the colour where
                                         the alpha test passes (at CUTOFF, 0.5 by default) on the
                                         uncompressed surface, and the alpha test's IoU, of
                                         cirrus's level 0 and of bc7enc's at its top uber level on
                                         the same surface (BC7's decoding is exact integer
                                         arithmetic: one decoder judges both)

Needs `pip install quicktex pillow numpy` (a venv); `bc7-visible` needs `etcpak` (bc7enc) and
`texture2ddecoder` instead of quicktex."""

import math
import os
import struct
import sys

import numpy as np
from PIL import Image


def psnr(squared_error, samples):
    return 10 * math.log10(255 * 255 / max(squared_error / samples, 1e-12))


def bc1_decode(blocks, width, height):
    """BC1 blocks to float RGB, four-colour and three-colour modes."""
    words = np.frombuffer(blocks, dtype="<u2").reshape(-1, 4)
    c0, c1 = words[:, 0].astype(np.int64), words[:, 1].astype(np.int64)
    indices = words[:, 2].astype(np.int64) | (words[:, 3].astype(np.int64) << 16)

    def rgb(c):
        return np.stack([(c >> 11 & 31) / 31, (c >> 5 & 63) / 63, (c & 31) / 31], axis=1) * 255

    p0, p1 = rgb(c0), rgb(c1)
    four = (c0 > c1)[:, None]
    palette = np.stack([p0, p1, np.where(four, (2 * p0 + p1) / 3, (p0 + p1) / 2),
                        np.where(four, (p0 + 2 * p1) / 3, 0.0)], axis=1)
    out = np.zeros((height, width, 3))
    blocks_x = width // 4
    for texel in range(16):
        index = indices >> (2 * texel) & 3
        colour = palette[np.arange(len(index)), index]
        out[texel // 4::4, texel % 4::4] = colour.reshape(height // 4, blocks_x, 3)
    return out


def ktx2_level0(path):
    data = open(path, "rb").read()
    width, height = struct.unpack("<II", data[20:28])
    offset, length = struct.unpack("<QQ", data[80:96])
    return data[offset:offset + length], width, height


def bc1(folders):
    import quicktex
    from quicktex.s3tc.bc1 import BC1Encoder
    for folder in folders:
        reference = np.array(Image.open(os.path.join(folder, "mra.png")).convert("RGBA"))
        height, width = reference.shape[:2]
        blocks, ktx_width, ktx_height = ktx2_level0(os.path.join(folder, "mra.ktx2"))
        assert (ktx_width, ktx_height) == (width, height) and width % 4 == 0 and height % 4 == 0
        raw = quicktex.RawTexture.frombytes(reference.tobytes(), width, height)
        theirs = BC1Encoder(18).encode(raw).tobytes()
        rgb = reference[:, :, :3].astype(float)
        samples = rgb.size
        ours_db = psnr(((rgb - bc1_decode(blocks, width, height)) ** 2).sum(), samples)
        theirs_db = psnr(((rgb - bc1_decode(theirs, width, height)) ** 2).sum(), samples)
        print(f"{folder}: mra BC1 cirrus {ours_db:.2f} dB, rgbcx level 18 {theirs_db:.2f} dB ({ours_db - theirs_db:+.2f})")


def bc4_palette(e0, e1):
    if e0 > e1:
        return [e0, e1] + [((7 - k) * e0 + k * e1) / 7 for k in range(1, 7)]
    return [e0, e1] + [((5 - k) * e0 + k * e1) / 5 for k in range(1, 5)] + [0.0, 255.0]


def bc4(root):
    import quicktex
    from quicktex.s3tc.bc4 import BC4Encoder
    for name in sorted(os.listdir(root)):
        for file, channels in (("normal", 2), ("ao", 1)):
            path = next((os.path.join(root, name, f"{file}.{extension}") for extension in ("png", "jpg")
                         if os.path.isfile(os.path.join(root, name, f"{file}.{extension}"))), None)
            if path is None:
                continue
            image = np.array(Image.open(path).convert("RGBA"))
            height, width = image.shape[0] // 4 * 4, image.shape[1] // 4 * 4
            image = np.ascontiguousarray(image[:height, :width])
            blocks_x = width // 4
            for channel in range(channels):
                data = BC4Encoder(channel).encode(quicktex.RawTexture.frombytes(image.tobytes(), width, height)).tobytes()
                total, samples = 0.0, 0
                for block in range(0, blocks_x * (height // 4), 37):
                    bx, by = block % blocks_x, block // blocks_x
                    bytes_ = data[block * 8:block * 8 + 8]
                    palette = bc4_palette(bytes_[0], bytes_[1])
                    indices = int.from_bytes(bytes_[2:8] + b"\0\0", "little")
                    for texel in range(16):
                        value = int(image[by * 4 + texel // 4, bx * 4 + texel % 4, channel])
                        total += (value - palette[indices >> (3 * texel) & 7]) ** 2
                    samples += 16
                print(f"{name}/{file} channel {channel}: rgbcx BC4 {psnr(total, samples):.2f} dB")


def bc7_visible(png, cutoff):
    import etcpak
    import texture2ddecoder
    reference = np.array(Image.open(png).convert("RGBA"))
    height, width = reference.shape[:2]
    blocks, ktx_width, ktx_height = ktx2_level0(os.path.splitext(png)[0] + ".ktx2")
    assert (ktx_width, ktx_height) == (width, height) and width % 4 == 0 and height % 4 == 0
    params = etcpak.BC7CompressBlockParams()
    params.init_linear_weights()
    params.m_uber_level = 4
    params.m_max_partitions = 64
    params.m_try_least_squares = True
    theirs = etcpak.compress_bc7(reference.tobytes(), width, height, params)
    # The alpha test passes where alpha / 255 >= cutoff, as a shader tests the unorm value.
    visible = reference[:, :, 3] / 255.0 >= cutoff

    def figures(data):
        # texture2ddecoder gives BGRA.
        decoded = np.frombuffer(texture2ddecoder.decode_bc7(data, width, height), np.uint8)
        decoded = decoded.reshape(height, width, 4)[:, :, [2, 1, 0, 3]].astype(float)
        error = ((decoded[:, :, :3] - reference[:, :, :3]) ** 2)[visible].sum()
        passes = decoded[:, :, 3] / 255.0 >= cutoff
        return psnr(error, visible.sum() * 3), (passes & visible).sum() / max((passes | visible).sum(), 1)

    (ours_db, ours_iou), (theirs_db, theirs_iou) = figures(blocks), figures(theirs)
    print(f"{png}: BC7 where the alpha test passes: cirrus {ours_db:.2f} dB (alpha-test IoU "
          f"{ours_iou:.4f}), bc7enc uber 4 {theirs_db:.2f} dB ({theirs_iou:.4f}), {ours_db - theirs_db:+.2f} dB")


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "bc1":
        bc1(sys.argv[2:])
    elif len(sys.argv) == 3 and sys.argv[1] == "bc4":
        bc4(sys.argv[2])
    elif len(sys.argv) in (3, 4) and sys.argv[1] == "bc7-visible":
        bc7_visible(sys.argv[2], float(sys.argv[3]) if len(sys.argv) == 4 else 0.5)
    else:
        sys.exit(__doc__)
