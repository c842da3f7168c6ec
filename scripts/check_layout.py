#!/usr/bin/env python3
"""Build-time check of the GLSL side of shaders/vkrt_shared.h.

The C side checks its layouts with _Static_assert. This script compiles
shaders/layout_check.comp (which uses every shared struct in a std430 buffer or the push
constants) with glslangValidator, disassembles it, and compares each member's std430 Offset
and each array's ArrayStride with the packed C layout the header declares (4-byte scalars,
12-byte VKRT_FLOAT3). Any difference fails the build, so a field that would land at another
offset in GLSL than in C is caught before a single pixel is traced."""
import os
import re
import subprocess
import sys
import tempfile

FIELD_SIZES = {"VKRT_FLOAT3": 12, "VKRT_UINT": 4, "float": 4, "int32_t": 4, "uint32_t": 4}


def c_layouts(header):
    text = open(header, encoding="utf-8").read()
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    layouts = {}
    for name, body in re.findall(r"VKRT_STRUCT\((\w+)\)\s*\{(.*?)\};", text, flags=re.S):
        offset, fields = 0, []
        for ftype, fname in re.findall(r"(\w+)\s+(\w+)\s*;", body):
            if ftype not in FIELD_SIZES:
                sys.exit(f"{header}: {name}.{fname} has type {ftype}, which the shared-layout rule does not allow")
            fields.append((fname, offset))
            offset += FIELD_SIZES[ftype]
        layouts[name] = (fields, offset)
    return layouts


def spirv_layouts(glslang, spirv_dis, shader):
    with tempfile.TemporaryDirectory() as tmp:
        spv = os.path.join(tmp, "layout.spv")
        compiled = subprocess.run([glslang, "-V", "--target-env", "vulkan1.2", "-o", spv, shader],
                                  capture_output=True, text=True)
        if compiled.returncode != 0:
            sys.exit(f"{shader} does not compile:\n{compiled.stdout}{compiled.stderr}")
        dis = subprocess.run([spirv_dis, "--raw-id", spv], check=True, capture_output=True, text=True).stdout
    names = dict(re.findall(r'OpName (%\d+) "(\w+)"', dis))
    offsets, strides, element = {}, {}, {}
    for sid, member, off in re.findall(r"OpMemberDecorate (%\d+) (\d+) Offset (\d+)", dis):
        offsets.setdefault(sid, {})[int(member)] = int(off)
    for aid, stride in re.findall(r"OpDecorate (%\d+) ArrayStride (\d+)", dis):
        strides[aid] = int(stride)
    for aid, elem in re.findall(r"(%\d+) = OpTypeRuntimeArray (%\d+)", dis):
        element[aid] = elem
    return names, offsets, strides, element


def main():
    glslang, spirv_dis, header, shader, stamp = sys.argv[1:6]
    layouts = c_layouts(header)
    names, offsets, strides, element = spirv_layouts(glslang, spirv_dis, shader)
    errors, seen = [], set()
    for sid, members in offsets.items():
        name = names.get(sid)
        if name not in layouts:
            continue
        seen.add(name)
        fields, _ = layouts[name]
        if len(members) != len(fields):
            errors.append(f"{name}: GLSL has {len(members)} members, C {len(fields)}")
            continue
        for index, (fname, c_off) in enumerate(fields):
            if members[index] != c_off:
                errors.append(f"{name}.{fname}: std430 offset {members[index]}, C offset {c_off}")
    for aid, stride in strides.items():
        name = names.get(element.get(aid))
        if name in layouts and stride != layouts[name][1]:
            errors.append(f"{name}[]: std430 array stride {stride}, C sizeof {layouts[name][1]}")
    missing = set(layouts) - seen
    if missing:
        errors.append(f"{os.path.basename(shader)} does not use {', '.join(sorted(missing))}: add them so they are checked")
    if errors:
        sys.exit("shared layout mismatch between C and GLSL:\n  " + "\n  ".join(errors))
    with open(stamp, "w", encoding="utf-8") as f:
        f.write("".join(f"{n}: {s} bytes\n" for n, (_, s) in sorted(layouts.items())))


if __name__ == "__main__":
    main()
