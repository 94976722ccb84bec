"""The BC1 reference of the corpus tests: rgbcx at its top level (Python `quicktex`, BC1
level 18) on cirrus's packed mra surfaces (the uncompressed level 0 a build writes as
`mra.png`), decoded as `bcdec` decodes (cirrus's PSNR decoder), PSNR over R, G and B.

    python3 -m venv /tmp/venv && /tmp/venv/bin/pip install quicktex numpy pillow
    # a project whose pipeline bakes ../shared/assets/materials/*.mymaterial into baked/
    /tmp/venv/bin/python tools/rgbcx_mra.py baked
"""
import glob, sys, numpy, quicktex, quicktex.s3tc.bc1 as bc1
from PIL import Image

def bcdec_bc1(blocks):
    c0 = blocks[:, 0].astype(numpy.uint32) | (blocks[:, 1].astype(numpy.uint32) << 8)
    c1 = blocks[:, 2].astype(numpy.uint32) | (blocks[:, 3].astype(numpy.uint32) << 8)
    def unpack(c):
        return (c >> 11) & 31, (c >> 5) & 63, c & 31
    r0, g0, b0 = unpack(c0); r1, g1, b1 = unpack(c1)
    ex5 = lambda v: (v * 527 + 23) >> 6
    ex6 = lambda v: (v * 259 + 33) >> 6
    colors = numpy.zeros((len(blocks), 4, 3), numpy.int64)
    colors[:, 0] = numpy.stack([ex5(r0), ex6(g0), ex5(b0)], 1)
    colors[:, 1] = numpy.stack([ex5(r1), ex6(g1), ex5(b1)], 1)
    four = c0 > c1
    c2 = numpy.stack([((2*r0+r1)*351+61)>>7, ((2*g0+g1)*2763+1039)>>11, ((2*b0+b1)*351+61)>>7], 1)
    c3 = numpy.stack([((r0+2*r1)*351+61)>>7, ((g0+2*g1)*2763+1039)>>11, ((b0+2*b1)*351+61)>>7], 1)
    h2 = numpy.stack([((r0+r1)*1053+125)>>8, ((g0+g1)*4145+1019)>>11, ((b0+b1)*1053+125)>>8], 1)
    colors[:, 2] = numpy.where(four[:, None], c2, h2)
    colors[:, 3] = numpy.where(four[:, None], c3, 0)
    indices = blocks[:, 4].astype(numpy.uint32) | (blocks[:, 5].astype(numpy.uint32) << 8) | (blocks[:, 6].astype(numpy.uint32) << 16) | (blocks[:, 7].astype(numpy.uint32) << 24)
    texels = numpy.stack([(indices >> (2 * t)) & 3 for t in range(16)], 1)
    return numpy.take_along_axis(colors, texels[:, :, None].astype(numpy.int64), 1)  # blocks × 16 × 3

for path in sorted(glob.glob(sys.argv[1] + "/**/mra.png", recursive=True)):
    image = numpy.array(Image.open(path).convert("RGBA"))
    height, width = image.shape[0] // 4 * 4, image.shape[1] // 4 * 4
    image = numpy.ascontiguousarray(image[:height, :width])
    raw = quicktex.RawTexture.frombytes(image.tobytes(), width, height)
    encoded = bc1.BC1Encoder(18).encode(raw)
    data = numpy.frombuffer(bytes(encoded), numpy.uint8).reshape(-1, 8)
    decoded = bcdec_bc1(data)
    original = image.reshape(height // 4, 4, width // 4, 4, 4).transpose(0, 2, 1, 3, 4).reshape(-1, 16, 4)[:, :, :3].astype(numpy.int64)
    mse = ((decoded - original) ** 2).mean()
    print(f"{path}: rgbcx level 18 {10 * numpy.log10(255 * 255 / mse):.2f} dB")
