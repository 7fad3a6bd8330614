"""Known depth frames for the V4L2 VM test (scripts/test-v4l2-vm.sh --deard).

Writes N raw 'Y16 ' frames (little-endian u16 millimetres, W x H) to stdout: a checkerboard
of depths between 0.8 and 1.2 m that differs per frame, with an invalid (0) block and a block
beyond the test module's 4 m range (scripts/v4l2-vm/module.toml max_range_m; 4.2 m and more),
so a received frame identifies which fed frame it is and shows that invalid stays invalid and
that depth beyond the range is published invalid.
Usage: fed_frames.py W H N > fed.y16
"""

import sys
from array import array


def frame(width: int, height: int, k: int) -> array:
    values = array("H", bytes(2 * width * height))
    for y in range(height):
        row = y * width
        for x in range(width):
            invalid = 100 <= y < 140 and 200 <= x < 260
            beyond_range = 300 <= y < 340 and 400 <= x < 460
            if invalid:
                values[row + x] = 0
            elif beyond_range:
                values[row + x] = 4200 + 40 * k + x - 400
            else:
                values[row + x] = 800 + 40 * k + 50 * ((x // 16 + y // 16 + k) % 8)
    return values


def main() -> None:
    width, height, n = (int(a) for a in sys.argv[1:4])
    out = sys.stdout.buffer
    for k in range(n):
        values = frame(width, height, k)
        if sys.byteorder != "little":
            values.byteswap()
        out.write(values.tobytes())


if __name__ == "__main__":
    main()
