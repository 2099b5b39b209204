"""The search-then-go ObjectNav expert (navcore.nav.search): what its camera sees, that it
searches while the goal is out of sight and reaches it, and that with the goal in view it is the
geodesic oracle itself."""
import math

import numpy as np

from navcore.eval.env import EnvConfig, NavEnv
from navcore.nav.actions import STOP
from navcore.nav.oracle import DiscreteOracle
from navcore.nav.poses import point_regions
from navcore.nav.search import SearchingExpert


def expert_for(ctx, ep):
    regions = point_regions(np.asarray(ep.goal_sources))
    goal = DiscreteOracle(ctx.field(ep).grid, ctx.costmap, regions, ep.success_radius)
    return SearchingExpert(ctx.graph, goal, regions, ep.success_radius, hfov_deg=90.0), goal


def drive(ctx, ep, policy, steps=400):
    env = NavEnv(ctx, EnvConfig(render=False, protocol="explicit_stop"))
    env.reset(ep)
    s, trace = env.state, []
    while not s.done and s.steps < steps:
        a = policy(s.x, s.y, s.yaw)
        trace.append((s.x, s.y, a))
        env.step(STOP if a < 0 else a)
    return s, trace


def test_what_the_camera_sees(ctx, make_episode):
    """Facing +x from (1.0, 1.5) in the left half of the room: the floor ahead is seen, the floor
    behind and the room behind the wall at x = 2 m are not."""
    ep = make_episode(start=(1.0, 1.5, 0.0), goal=(3.0, 0.5), radius=0.3, task="objectnav")
    ex, _ = expert_for(ctx, ep)
    ex.look(1.0, 1.5, 0.0)
    seen = lambda x, y: bool(ex.seen[tuple(ctx.costmap.cells_of(np.array([[x, y]]))[0])])  # noqa: E731
    assert seen(1.5, 1.5) and seen(1.9, 1.7) and not seen(0.5, 1.5) and not seen(3.0, 1.5) and not seen(1.0, 0.2)
    assert not ex.found


def test_it_searches_while_the_goal_is_hidden_and_then_reaches_it(ctx, make_episode):
    """Start facing away from the door, the goal behind the wall: the goal is found only once the
    robot has looked through the door, and the episode ends with STOP inside the region."""
    ep = make_episode(start=(1.0, 0.5, math.pi), goal=(3.0, 0.5), radius=0.3, max_steps=600, task="objectnav")
    ex, goal = expert_for(ctx, ep)
    found_at = []

    def policy(x, y, yaw):
        a = ex.action(x, y, yaw)
        found_at.append(ex.found)
        return a

    s, trace = drive(ctx, ep, policy)
    assert s.done and s.success and trace[-1][2] == STOP
    first = found_at.index(True)
    assert first > 0 and not found_at[0]
    # it was found from near the door (the only line of sight into the right half), not before
    x, y, _ = trace[first]
    assert x > 1.2 and y > 1.2, (x, y)
    assert len(trace) > len(goal.episode(ep.start)) + 5  # searching costs steps the oracle does not take


def test_with_the_goal_in_view_it_is_the_geodesic_oracle(ctx, make_episode):
    ep = make_episode(start=(3.0, 2.0, -math.pi / 2), goal=(3.0, 0.5), radius=0.3, max_steps=200, task="objectnav")
    ex, goal = expert_for(ctx, ep)
    steps = []
    s, trace = drive(ctx, ep, lambda x, y, yaw: steps.append((ex.action(x, y, yaw), goal.action(x, y, yaw))) or
                     steps[-1][0])
    assert s.success and ex.found
    assert all(a == b for a, b in steps)
    assert [a for _, _, a in trace] == list(goal.episode(ep.start))


def test_same_poses_same_actions(ctx, make_episode):
    ep = make_episode(start=(1.0, 0.5, math.pi), goal=(3.0, 0.5), radius=0.3, max_steps=600, task="objectnav")
    runs = []
    for _ in range(2):
        ex, _ = expert_for(ctx, ep)
        runs.append(drive(ctx, ep, ex.action)[1])
    assert runs[0] == runs[1]


def test_imagenav_found_means_the_goal_image_is_in_view(ctx, make_episode):
    """ImageNav's goal view: the goal camera at (3.0, 1.5) faces the east wall. Standing on the goal's
    floor facing the other way is not found (the region criterion says found: its own floor is
    seen); facing east from 0.5 m behind it is; nothing of the east wall is visible through the
    dividing wall from the left room."""
    ep = make_episode(start=(1.0, 0.5, math.pi), goal=(3.0, 1.5), radius=0.3, max_steps=600, task="imagenav", goal_yaw=0.0)
    regions = point_regions(np.asarray(ep.goal_sources))
    goal = DiscreteOracle(ctx.field(ep).grid, ctx.costmap, regions, ep.success_radius)
    view = SearchingExpert(ctx.graph, goal, regions, ep.success_radius, hfov_deg=90.0, goal_view=(3.0, 1.5, 0.0))
    glimpse, _ = expert_for(ctx, ep)
    wall = view.goal_points
    assert len(wall) > 10 and np.allclose(wall[:, 0], 3.95, atol=0.1) and wall[:, 1].min() < 0.7 and wall[:, 1].max() > 2.3
    assert not view.visible(1.0, 1.5, 0.0, wall).any()  # behind the dividing wall
    assert view.visible(2.5, 1.5, 0.0, wall).mean() > 0.8
    glimpse.look(3.0, 1.5, math.pi)
    view.look(3.0, 1.5, math.pi)
    assert glimpse.found and not view.found
    view.look(2.5, 1.5, 0.0)
    assert view.found


def test_imagenav_expert_searches_until_the_view_matches_then_reaches_the_goal(ctx, make_episode):
    ep = make_episode(start=(1.0, 0.5, math.pi), goal=(3.0, 1.5), radius=0.3, max_steps=600, task="imagenav", goal_yaw=0.0)
    regions = point_regions(np.asarray(ep.goal_sources))
    goal = DiscreteOracle(ctx.field(ep).grid, ctx.costmap, regions, ep.success_radius)
    ex = SearchingExpert(ctx.graph, goal, regions, ep.success_radius, hfov_deg=90.0, goal_view=(3.0, 1.5, 0.0))
    found = []
    s, trace = drive(ctx, ep, lambda x, y, yaw: (ex.action(x, y, yaw), found.append((ex.found, yaw)))[0])
    assert s.success and trace[-1][2] == STOP
    first = [f for f, _ in found].index(True)
    x, _, _ = trace[first]
    assert x > 1.8 and math.cos(found[first][1]) > 0  # at the door or beyond it, looking east


def test_the_next_target_is_the_nearest_unseen_cell_past_min_hop(ctx, make_episode):
    """_pick against a brute force over the unbounded geodesic field: the nearest valid unseen cell
    at least min_hop away, the first in row-major order among equals (its staged, bounded searches
    give that cell), or False when there is none."""
    ep = make_episode(start=(1.0, 0.5, 0.0), goal=(3.0, 0.5), radius=0.3, task="objectnav")
    rng = np.random.default_rng(5)
    cells = ctx.graph.cells[rng.choice(len(ctx.graph.cells), 40, replace=False)]
    for k, cell in enumerate(cells):
        ex, _ = expert_for(ctx, ep)
        ex.horizon = (1.2, 6.0)[k % 2]
        ex.seen = rng.random(ex.seen.shape) < (0.2, 0.6, 0.97, 1.0)[k % 4]
        x, y = ctx.costmap.cell_centers(cell[None])[0]
        d = ctx.graph.field(cell[None]).grid
        cand = np.where(ctx.graph.valid & ~ex.seen & (d >= ex.min_hop), d, np.inf)
        found = bool(np.isfinite(cand.min()))
        assert ex._pick(x, y) == found
        if found:
            want = ctx.costmap.cell_centers(np.array([np.unravel_index(int(np.argmin(cand)), cand.shape)]))[0]
            assert np.array_equal(ex.target, want)
