"""Speed of the simulator with the ECU core in the loop: simulated seconds per wall second.

One hour of field work (passes of 200 m at 8 km/h with headland stops and turns, four crop
sensors, GNSS at 5 Hz, the cab PC on a virtual CAN bus) must take at most 10 s.
Prints `sim_realtime_ratio: N`.
"""

from __future__ import annotations

import argparse
import time

from topdress.sim.sil import Sil
from topdress.sim.tractor import Drive
from topdress.sim.world import World


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=3600.0, help="simulated time")
    ap.add_argument("--profile", action="store_true", help="print the top of a cProfile")
    args = ap.parse_args()
    world = World(seed=1, drive=Drive.field_passes(passes=200, length_m=200.0, speed_kmh=8.0))
    steps = round(args.seconds / world.dt)
    with Sil(world) as sil:
        if args.profile:
            import cProfile
            import pstats

            prof = cProfile.Profile()
            prof.enable()
        t0 = time.perf_counter()
        c0 = time.process_time()
        for _ in range(steps):
            sil.step()
        wall = time.perf_counter() - t0
        cpu = time.process_time() - c0
        if args.profile:
            prof.disable()
            pstats.Stats(prof).sort_stats("tottime").print_stats(15)
        print(f"simulated_s: {world.t_s:.0f}")
        print(f"wall_s: {wall:.2f}")
        print(f"cpu_s: {cpu:.2f}")
        print(f"distance_m: {world.tractor.odometer:.0f}")
        print(f"nmea_lines: {sil.nmea_lines}")
        print(f"crop_lines: {sil.crop_lines}")
        print(f"status_samples: {len(sil.record.rows) if sil.record else 0}")
        print(f"sim_realtime_ratio: {world.t_s / wall:.0f}")
        # the process's CPU time: the figure on a machine shared with other work
        print(f"sim_cpu_ratio: {world.t_s / cpu:.0f}")


if __name__ == "__main__":
    main()
