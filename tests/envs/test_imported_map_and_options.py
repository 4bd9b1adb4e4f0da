import shutil

import numpy as np

from hbmp_bench.envs import BehaviorEnv
from hbmp_bench.maps import import_map, net_path


def test_imported_map_is_usable_as_a_town(tmp_path, monkeypatch):
    monkeypatch.setenv("HBMP_BENCH_DATA", str(tmp_path))
    src = tmp_path / "mine.net.xml"
    shutil.copy(net_path("Town02"), src)
    import_map(src, "MyTown")
    env = BehaviorEnv(town="MyTown", task="OneTurn", episode_index=0)
    obs, info = env.reset(seed=0)
    obs, *_ = env.step(0)
    env.close()
    assert obs["road"].shape == (10,)


def test_vehicle_centric_grid_differs_from_deformed_on_a_turn():
    grids = {}
    for kind in ("deformed", "vehicle_centric"):
        env = BehaviorEnv(town="Town01", task="NavigationDynamic", episode_index=1, observation=kind)
        obs, _ = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        total = np.zeros_like(obs["occupancy"])
        for _ in range(300):
            obs, _, terminated, truncated, _ = env.step(0 if obs["road"][9] < 0.6 else 4)
            total += obs["occupancy"]
            if terminated or truncated:
                break
        env.close()
        grids[kind] = total
    assert grids["deformed"].sum() > 0 and grids["vehicle_centric"].sum() > 0
    assert not np.array_equal(grids["deformed"], grids["vehicle_centric"])


def test_record_says_what_traffic_spawned(tmp_path, monkeypatch):
    monkeypatch.setenv("HBMP_BENCH_DATA", str(tmp_path))
    src = tmp_path / "mine.net.xml"
    shutil.copy(net_path("Town02"), src)
    import_map(src, "MyTown", like="Town02")
    env = BehaviorEnv(town="MyTown", task="NavigationDynamic", episode_index=0, fidelity="event")
    env.reset(seed=0)
    record = env.record()
    persons = env.world.sim._api.person.getIDCount()
    env.close()
    asked = env.episodes[0].traffic
    assert (record.traffic_vehicles, record.traffic_pedestrians) == (asked.vehicles, persons) == (15, 50)


def test_background_routes_stop_at_a_dead_end(tmp_path, monkeypatch):
    """A background vehicle's circulating route ends where no drivable link leads on (real towns have
    such edges once links sharper than a car can turn are left out: CARLA's Town07 hung every
    NavigationDynamic reset looking for a way on)."""
    from hbmp_bench.envs.config import WorldConfig
    from hbmp_bench.envs.world import DrivingWorld
    from hbmp_bench.maps.netconvert import run_netconvert

    monkeypatch.setenv("HBMP_BENCH_DATA", str(tmp_path / "data"))
    (tmp_path / "n.nod.xml").write_text('<nodes><node id="a" x="0" y="0"/><node id="b" x="200" y="0"/>'
                                        '<node id="c" x="400" y="0"/></nodes>', encoding="utf-8")
    (tmp_path / "n.edg.xml").write_text('<edges><edge id="first" from="a" to="b" numLanes="1" speed="13.89"/>'
                                        '<edge id="last" from="b" to="c" numLanes="1" speed="13.89"/></edges>',
                                        encoding="utf-8")
    run_netconvert(["-n", "n.nod.xml", "-e", "n.edg.xml", "-o", "line.net.xml"], cwd=tmp_path)
    import_map(tmp_path / "line.net.xml", "line")
    world = DrivingWorld("line", WorldConfig())
    rng = np.random.default_rng(0)
    assert world.long_route(rng, "last") == ["last"]
    assert world.long_route(rng, "first") == ["first", "last"]
