#!/usr/bin/env python3
"""Writes the texture seeds of the glTF fuzzer (scripts/fuzz): one small GLB per image format,
a triangle whose material's base colour texture is that image, embedded in the binary chunk so
that the fuzzer's byte mutations reach the decoder directly. Every image is written here byte by
byte (no image library, no copied file): the formats vkrt decodes (PNG, baseline and progressive
JPEG, TGA, BMP in their common variants) and those it refuses (GIF, PSD, PIC, HDR, PNM), whose
bytes a loose format test (TGA has no magic number) could still hand to a decoder.
Usage: python3 tests/fuzz/seeds/make_seeds.py   (rewrites the .glb files beside it)"""
import json
import os
import struct
import zlib

W = H = 4
PIXELS = [(x * 60, y * 60, 128) for y in range(H) for x in range(W)]


def png():
    def chunk(kind, data):
        return struct.pack('>I', len(data)) + kind + data + struct.pack('>I', zlib.crc32(kind + data))
    rows = b''.join(b'\0' + b''.join(bytes(p) for p in PIXELS[y * W:(y + 1) * W]) for y in range(H))
    return (b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', W, H, 8, 2, 0, 0, 0)) +
            chunk(b'IDAT', zlib.compress(rows)) + chunk(b'IEND', b''))


# JPEG: 8 bits, every coefficient 0; each Huffman table one code of one bit (DC category 0, AC
# end of block), so the entropy-coded data is a few bits a block.
SOI, EOI = b'\xff\xd8', b'\xff\xd9'
DQT = bytes([0xFF, 0xDB, 0, 67, 0]) + bytes([1] * 64)
DHT_DC = bytes([0xFF, 0xC4, 0, 20, 0x00, 1] + [0] * 15 + [0])
DHT_AC = bytes([0xFF, 0xC4, 0, 20, 0x10, 1] + [0] * 15 + [0])


def sof(marker, width, height, components):
    body = bytes([8, height >> 8, height & 255, width >> 8, width & 255, len(components)])
    for i, sampling in enumerate(components):
        body += bytes([i + 1, sampling, 0])
    return bytes([0xFF, marker]) + struct.pack('>H', 2 + len(body)) + body


def sos(count, start, end):
    body = bytes([count]) + b''.join(bytes([i + 1, 0x00]) for i in range(count)) + bytes([start, end, 0])
    return b'\xff\xda' + struct.pack('>H', 2 + len(body)) + body


def jpeg_baseline():
    return SOI + DQT + sof(0xC0, 8, 8, [0x11]) + DHT_DC + DHT_AC + sos(1, 0, 63) + b'\x3f' + EOI


def jpeg_progressive():
    return (SOI + DQT + sof(0xC2, 8, 8, [0x11]) + DHT_DC + sos(1, 0, 0) + b'\x7f' + DHT_AC + sos(1, 1, 63) +
            b'\x7f' + EOI)


def jpeg_ycc_420():
    # 16x16, Y sampled 2x2: one MCU of four Y blocks, Cb and Cr, each DC 0 and end of block.
    return SOI + DQT + sof(0xC0, 16, 16, [0x22, 0x11, 0x11]) + DHT_DC + DHT_AC + sos(3, 0, 63) + b'\x00\x0f' + EOI


def jpeg_restart():
    dri = bytes([0xFF, 0xDD, 0, 4, 0, 1])
    return SOI + DQT + dri + sof(0xC0, 16, 8, [0x11]) + DHT_DC + DHT_AC + sos(1, 0, 63) + b'\x3f\xff\xd0\x3f' + EOI


def tga(kind, bits, data, colour_map=b'', map_entries=0, descriptor=0):
    head = struct.pack('<BBBHHBHHHHBB', 0, 1 if colour_map else 0, kind, 0, map_entries, 24 if colour_map else 0,
                       0, 0, W, H, bits, descriptor)
    return head + colour_map + data


def bmp(bits, data, palette=()):
    pal = b''.join(bytes([b, g, r, 0]) for r, g, b in palette)
    offset = 14 + 40 + len(pal)
    info = struct.pack('<IiiHHIIiiII', 40, W, H, 1, bits, 0, len(data), 2835, 2835, len(palette), 0)
    return b'BM' + struct.pack('<IHHI', offset + len(data), 0, 0, offset) + info + pal + data


PALETTE = [(255, 0, 0), (0, 255, 0), (0, 0, 255), (9, 9, 9)]
BGR = b''.join(bytes([b, g, r]) for r, g, b in PIXELS)


def gif():
    # 1x1, a two-colour table, one pixel LZW-coded as clear, 0, end.
    return (b'GIF89a' + bytes([1, 0, 1, 0, 0x80, 0, 0, 200, 20, 10, 0, 0, 0]) + b',' +
            bytes([0, 0, 0, 0, 1, 0, 1, 0, 0, 2, 2, 0x44, 0x01, 0]) + b';')


def psd():
    head = b'8BPS' + struct.pack('>H6xHIIHH', 1, 3, H, W, 8, 3) + struct.pack('>III', 0, 0, 0) + struct.pack('>H', 0)
    return head + b''.join(bytes(p[c] for p in PIXELS) for c in range(3))


def pic():
    head = b'\x53\x80\xf6\x34' + struct.pack('>f', 3.71) + bytes(80) + b'PICT' + struct.pack('>HHfHH', W, H, 1.0, 3, 0)
    return head + bytes([0, 8, 0, 0xE0]) + b''.join(bytes(p) for p in PIXELS)


def hdr():
    return (b'#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %d +X %d\n' % (H, W) +
            b''.join(bytes([p[0], p[1], p[2], 128]) for p in PIXELS))


IMAGES = {
    'png': png(),
    'jpeg_baseline': jpeg_baseline(),
    'jpeg_progressive': jpeg_progressive(),
    'jpeg_ycc_420': jpeg_ycc_420(),
    'jpeg_restart': jpeg_restart(),
    'tga_truecolour': tga(2, 24, BGR),
    'tga_rle': tga(10, 24, b''.join(b'\x00' + BGR[i:i + 3] for i in range(0, len(BGR), 3))),
    'tga_grey': tga(3, 8, bytes(range(W * H))),
    'tga_alpha': tga(2, 32, bytes(range(W * H * 4)), descriptor=8),
    'tga_colour_mapped_rle': tga(9, 8, bytes([0x8F, 1]), b'\x00\x00\x00\xff\xff\xff', 2),
    'bmp_24': bmp(24, BGR),
    'bmp_8': bmp(8, bytes((x + y) % 4 for y in range(H) for x in range(W)), PALETTE),
    'bmp_4': bmp(4, bytes([0x01, 0x23, 0, 0]) * H, PALETTE),
    'bmp_16': bmp(16, b''.join(struct.pack('<H', (x * 8) << 10 | (y * 8) << 5 | 15) for y in range(H) for x in range(W))),
    'gif': gif(),
    'psd': psd(),
    'pic': pic(),
    'hdr': hdr(),
    'pgm_16_bit': b'P5\n4 4\n525\n' + bytes(range(32)),
}


def glb(image):
    positions = struct.pack('<9f', 0, 0, 0, 1, 0, 0, 0, 1, 0)
    uvs = struct.pack('<6f', 0, 0, 1, 0, 0, 1)
    binary = positions + uvs + image
    binary += b'\0' * (-len(binary) % 4)
    gltf = {
        'asset': {'version': '2.0'}, 'scene': 0, 'scenes': [{'nodes': [0]}], 'nodes': [{'mesh': 0}],
        'meshes': [{'primitives': [{'attributes': {'POSITION': 0, 'TEXCOORD_0': 1}, 'material': 0}]}],
        'materials': [{'pbrMetallicRoughness': {'baseColorTexture': {'index': 0}}}],
        'textures': [{'source': 0}], 'images': [{'bufferView': 2, 'mimeType': 'image/png'}],
        'accessors': [{'bufferView': 0, 'componentType': 5126, 'count': 3, 'type': 'VEC3', 'min': [0, 0, 0],
                       'max': [1, 1, 0]},
                      {'bufferView': 1, 'componentType': 5126, 'count': 3, 'type': 'VEC2'}],
        'bufferViews': [{'buffer': 0, 'byteOffset': 0, 'byteLength': 36},
                        {'buffer': 0, 'byteOffset': 36, 'byteLength': 24},
                        {'buffer': 0, 'byteOffset': 60, 'byteLength': len(image)}],
        'buffers': [{'byteLength': len(binary)}],
    }
    text = json.dumps(gltf, separators=(',', ':')).encode()
    text += b' ' * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(binary)
    return (struct.pack('<III', 0x46546C67, 2, total) + struct.pack('<II', len(text), 0x4E4F534A) + text +
            struct.pack('<II', len(binary), 0x004E4942) + binary)


here = os.path.dirname(os.path.abspath(__file__))
for name, image in IMAGES.items():
    with open(os.path.join(here, 'texture_%s.glb' % name), 'wb') as f:
        f.write(glb(image))
