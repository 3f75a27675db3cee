"""The five sites of the paper's Table 1, built as labelled scenes.

Local metres, z up, ground at z = 0, the building roughly centred on the origin. Each
builder takes ``rng`` (seeds a small jitter of proportions and clutter; None: nominal)
and returns a :class:`~scenes.scene.Scene`; element counts never depend on ``rng``.
The registry, descriptions and expected counts are in :mod:`scenes.sites`; the layouts
are described in ``docs/scenes.md``.
"""

from __future__ import annotations

import numpy as np

from hollowtree.classes import ClassId
from hollowtree.scenes._builders import (
    Jitter,
    RngLike,
    add_arcade,
    add_clutter,
    add_ground,
    add_stations,
    rect,
    room,
    wall_piece,
)
from hollowtree.scenes.elements import (
    arcade,
    bastion,
    chattri,
    dome,
    minaret,
    portal,
    roof_slab,
)
from hollowtree.scenes.scene import Scene, SceneBuilder
from hollowtree.scenes.shapes import ArcPath, StraightPath, slab, wall_panel

__all__ = ["derawar", "khudabad", "roman", "temple", "wazir_khan"]


# --------------------------------------------------------------------------- Wazir Khan
def wazir_khan(rng: RngLike = None) -> Scene:
    """Masjid Wazir Khan: 46 arches, 12 domes, 6 minarets; building 91 x 53 x 33 m.

    West: prayer hall (x -45.5..-32, roof 12 m) behind a 7-arch facade (a central
    pishtaq and 3 bays each side) under 5 domes seen through holes in its roof slab.
    North and south: ranges of cells behind 17-bay arcades (roof 7.5 m) with a chattri
    at each end (4). East: gateway range (roof 9.5 m) with a 5-arch outer facade (a
    portal and 2 bays each side), a dome and 2 chattris, and 2 small minarets flanking the
    portal. Four octagonal 33 m minarets stand at the courtyard corners.
    """
    j = Jitter(rng)
    b = SceneBuilder("wazir_khan")
    X0, X1, Y0, Y1 = -45.5, 45.5, -26.5, 26.5
    XH, XG, YC = -32.0, 36.0, 20.0  # hall facade, gateway inner wall, cell arcades (|y|)
    H_HALL, H_CELL, H_GATE = 12.0, 7.5, 9.5
    tw = 1.5
    # --- enclosure walls (outer), split by the roof heights behind them
    west = StraightPath(x0=X0 + tw / 2, y0=Y0, x1=X0 + tw / 2, y1=Y1)
    wall_piece(b, west, "west wall (hall back)", u0=0.0, u1=west.length, z1=H_HALL, thickness=tw)
    for side, y in (("north", Y1 - tw / 2), ("south", Y0 + tw / 2)):
        p = StraightPath(x0=X0, y0=y, x1=X1, y1=y)
        wall_piece(b, p, f"{side} wall (hall)", u0=0.0, u1=XH - X0, z1=H_HALL, thickness=tw)
        wall_piece(b, p, f"{side} wall (cells)", u0=XH - X0, u1=XG - X0, z1=H_CELL, thickness=tw)
        wall_piece(b, p, f"{side} wall (gateway)", u0=XG - X0, u1=X1 - X0, z1=H_GATE, thickness=tw)
    # --- prayer hall facade (x = XH), u along +y from Y0
    fac = StraightPath(x0=XH, y0=Y0, x1=XH, y1=Y1)
    t_fac = 1.2
    bay = j(4.0, 0.02)
    w_portal = 33.0 - 6 * bay
    ua = 10.0
    wall_piece(b, fac, "hall facade south end", u0=0.0, u1=ua, z1=H_HALL, thickness=t_fac)
    spring = j(4.2)
    for k, u_s in enumerate((ua, ua + 3 * bay + w_portal)):
        parts = arcade(fac, n_bays=3, u_start=u_s, bay_width=bay, span=0.65 * bay, spring=spring,
                       kind="pointed", pointedness=0.75, height=H_HALL, thickness=t_fac)
        add_arcade(b, parts, f"hall arcade {'south' if k == 0 else 'north'}")
    up0 = ua + 3 * bay
    b.add(portal(fac, u0=up0, u1=up0 + w_portal, span=0.66 * w_portal, spring=j(6.5),
                 height=j(16.0, 0.02), thickness=2.6, kind="pointed", pointedness=0.9),
          ClassId.ARCH, "hall portal (pishtaq)")
    wall_piece(b, fac, "hall facade north end", u0=ua + 33.0, u1=fac.length, z1=H_HALL,
               thickness=t_fac)
    # --- prayer hall roof and its five domes
    xd = 0.5 * ((X0 + tw) + (XH - t_fac / 2))
    hall_domes = [(0.0, j(5.0, 0.02), "pointed", j(2.4)), (10.5, j(3.6), "pointed", j(1.8)),
                  (-10.5, j(3.6), "pointed", j(1.8)), (19.0, j(3.0), "hemispherical", j(1.5)),
                  (-19.0, j(3.0), "hemispherical", j(1.5))]
    drum_t = 0.5
    b.add(roof_slab(rect(X0, XH + t_fac / 2, Y0, Y1), z=H_HALL, thickness=0.6,
                    holes=[(xd, y, r - drum_t) for y, r, _, _ in hall_domes]), ClassId.ROOF, "hall roof")
    for y, r, kind, dh in hall_domes:
        b.add(dome(center=(xd, y, H_HALL), kind=kind, radius=r, drum_height=dh, drum_thickness=drum_t,
                   thickness=0.35, finial=0.35 * r, pointedness=1.3),
              ClassId.DOME, f"hall dome y={y:+.1f}")
    # --- cell ranges: arcades on y = +-YC, end walls, roofs, chattris
    for side, sgn in (("north", 1.0), ("south", -1.0)):
        p = StraightPath(x0=XH, y0=sgn * YC, x1=XG, y1=sgn * YC)
        e0, e1 = 3.5, (XG - XH) - 3.5
        pitch = (e1 - e0) / 17
        wall_piece(b, p, f"{side} arcade west end", u0=0.0, u1=e0, z1=H_CELL - 0.5, thickness=1.0)
        parts = arcade(p, n_bays=17, u_start=e0, bay_width=pitch, span=j(0.64 * pitch, 0.02),
                       spring=j(2.6), kind="four_centred", height=H_CELL - 0.5, thickness=1.0,
                       cap_start=False, cap_end=False)
        add_arcade(b, parts, f"{side} cell arcade")
        wall_piece(b, p, f"{side} arcade east end", u0=e1, u1=XG - XH, z1=H_CELL - 0.5, thickness=1.0)
        ya, yb = sorted((sgn * (YC - 0.5), sgn * (Y1 - tw)))
        b.add(roof_slab(rect(XH + t_fac / 2, XG, ya, yb), z=H_CELL, thickness=0.5), ClassId.ROOF,
              f"{side} cell roof")
        for xc in (XH + 5.0, XG - 4.5):
            b.add(chattri(center=(xc, sgn * 23.25, H_CELL), radius=j(1.3), n_posts=4,
                          post_height=j(2.2)), ClassId.DOME, f"{side} chattri x={xc:+.1f}")
    # --- gateway range
    gin = StraightPath(x0=XG, y0=Y0, x1=XG, y1=Y1)
    wall_piece(b, gin, "gateway inner wall", u0=0.0, u1=gin.length, z1=H_GATE, thickness=1.2)
    xo = X1 - tw / 2
    gout = StraightPath(x0=xo, y0=Y0, x1=xo, y1=Y1)
    gbay = j(3.5, 0.02)
    w_gp = 8.0
    g0 = 26.5 - 0.5 * w_gp - 2 * gbay
    wall_piece(b, gout, "gateway facade south", u0=0.0, u1=g0, z1=H_GATE, thickness=tw)
    for k, u_s in enumerate((g0, g0 + 2 * gbay + w_gp)):
        parts = arcade(gout, n_bays=2, u_start=u_s, bay_width=gbay, span=0.63 * gbay, spring=j(3.2),
                       kind="pointed", pointedness=0.8, height=H_GATE, thickness=tw)
        add_arcade(b, parts, f"gateway arcade {'south' if k == 0 else 'north'}")
    gp0 = g0 + 2 * gbay
    b.add(portal(gout, u0=gp0, u1=gp0 + w_gp, span=5.0, spring=j(5.0), height=j(14.0, 0.02),
                 thickness=2.5, kind="pointed", pointedness=0.9), ClassId.ARCH, "gateway portal")
    wall_piece(b, gout, "gateway facade north", u0=gp0 + w_gp + 2 * gbay, u1=gout.length, z1=H_GATE,
               thickness=tw)
    xg = 0.5 * (XG + xo)
    g_r, g_dt = j(3.0), 0.4
    b.add(roof_slab(rect(XG, X1, Y0, Y1), z=H_GATE + 0.5, thickness=0.5,
                    holes=[(xg, 0.0, g_r - g_dt)]), ClassId.ROOF, "gateway roof")
    b.add(dome(center=(xg, 0.0, H_GATE + 0.5), kind="pointed", radius=g_r, drum_height=j(1.5),
               drum_thickness=g_dt, finial=1.0, pointedness=1.3), ClassId.DOME, "gateway dome")
    for y in (-12.0, 12.0):
        b.add(chattri(center=(xg, y, H_GATE + 0.5), radius=j(1.3), n_posts=4, post_height=j(2.2)),
              ClassId.DOME, f"gateway chattri y={y:+.0f}")
    # --- minarets
    for x in (XH, XG):
        for y in (-YC, YC):
            b.add(minaret(center=(x, y, 0.0), height=j(33.0, 0.01), base_radius=j(2.4, 0.02),
                          n_stages=4, n_segments=8), ClassId.MINARET, f"minaret ({x:+.0f}, {y:+.0f})")
    for y in (-0.5 * w_gp - 0.9, 0.5 * w_gp + 0.9):
        b.add(minaret(center=(X1 + 0.2, y, 0.0), height=j(18.0), base_radius=0.8, n_stages=2,
                      n_segments=8, balcony_depth=0.5, plinth_height=1.0),
              ClassId.MINARET, f"gateway minaret y={y:+.1f}")
    add_ground(b, -68.0, 70.0, -48.0, 48.0)
    add_clutter(b, j, [("tree", -56.0, -36.0, 0.0), ("tree", 58.0, 36.0, 0.0), ("tree", -57.0, 37.0, 0.0),
                       ("tree", 56.0, -37.0, 0.0), ("car", 60.0, 18.0, np.pi / 2),
                       ("car", -20.0, -38.0, 0.0), ("bench", 2.0, 15.5, 0.0),
                       ("bench", 2.0, -15.5, np.pi), ("bench", 12.0, 15.5, 0.0),
                       ("bicycle", 52.0, -9.0, 0.3), ("bicycle", 52.5, -7.0, 0.3)])
    add_stations(b, [(0.0, 6.0), (-62.0, 16.0), (-38.5, 0.0), (62.0, -14.0), (8.0, 42.0),
                     (-8.0, -42.0), (-20.0, -8.0), (26.0, 8.0), (-38.5, 14.5), (-38.5, -14.5),
                     (62.0, 14.0), (-60.0, -40.0), (60.0, 40.0), (-10.0, 12.0)])
    return b.build()


# --------------------------------------------------------------------------- Khudabad
def khudabad(rng: RngLike = None) -> Scene:
    """Masjid Khudabad: 12 arches, 21 domes; building 60 x 36 x 16 m.

    A prayer hall 60 x 36 m, roof slab at 8 m with 21 holes, under a 3 x 7 grid of
    pointed domes on drums; a 12-bay pointed arcade on the east-west front facade.
    """
    j = Jitter(rng)
    b = SceneBuilder("khudabad")
    X, Y, H, t = 30.0, 18.0, 8.0, 1.0
    h = t / 2
    back = StraightPath(x0=X, y0=Y - h, x1=-X, y1=Y - h)
    wall_piece(b, back, "back wall", u0=0.0, u1=back.length, z1=H - 0.5, thickness=t)
    for side, x in (("west", -X + h), ("east", X - h)):
        p = StraightPath(x0=x, y0=-Y, x1=x, y1=Y)
        wall_piece(b, p, f"{side} wall", u0=0.0, u1=p.length, z1=H - 0.5, thickness=t)
    front = StraightPath(x0=-X, y0=-Y + h, x1=X, y1=-Y + h)
    e = 1.0  # the first metre at each end lies inside the side walls
    pitch = (2 * X - 2 * e) / 12
    parts = arcade(front, n_bays=12, u_start=e, bay_width=pitch, span=j(0.62 * pitch, 0.02),
                   spring=j(3.2), kind="pointed", pointedness=0.8, height=H - 0.5, thickness=t,
                   cap_start=False, cap_end=False)
    add_arcade(b, parts, "front arcade")
    dx = 2 * X / 7
    r, drum_t = j(3.6), 0.45
    centres = [(-X + dx * (i + 0.5), y) for y in (-12.0, 0.0, 12.0) for i in range(7)]
    b.add(roof_slab(rect(-X, X, -Y, Y), z=H, thickness=0.5,
                    holes=[(x, y, r - drum_t) for x, y in centres]), ClassId.ROOF, "hall roof")
    drum_h = j(2.0)
    for k, (x, y) in enumerate(centres):
        b.add(dome(center=(x, y, H), kind="pointed", radius=r, pointedness=j(1.2, 0.02),
                   drum_height=drum_h, drum_thickness=drum_t, thickness=0.3, finial=1.0),
              ClassId.DOME, f"dome {k + 1} ({x:+.1f}, {y:+.1f})")
    add_ground(b, -52.0, 52.0, -42.0, 42.0)
    add_clutter(b, j, [("tree", -40.0, -30.0, 0.0), ("tree", 42.0, 28.0, 0.0), ("tree", -42.0, 26.0, 0.0),
                       ("car", 40.0, -32.0, 0.1), ("bench", -8.0, -26.0, 0.0),
                       ("bench", 8.0, -26.0, 0.0), ("bicycle", 20.0, -24.0, 0.4)])
    add_stations(b, [(0.0, -36.0), (-4.3, 6.0), (-38.0, 30.0), (40.0, 26.0), (-8.6, 6.0, H),
                     (20.0, -6.0), (-20.0, -6.0), (17.1, 6.0, H), (-40.0, -30.0), (0.0, 36.0),
                     (-25.7, 6.0, H), (38.0, -30.0)])
    return b.build()


# --------------------------------------------------------------------------- Derawar
def derawar(rng: RngLike = None) -> Scene:
    """Derawar Fort, scaled to a 200 x 170 m rectangle: 38 bastions and 38 curtain walls.

    Bastions (minaret class): 4 at the corners, 9 more along each long side and 8 along
    each short side; radius about 6 m, 25-29 m high, battered by 12 %. Curtain walls 20 m
    high, 4 m thick, one panel between each pair of neighbouring bastions.
    """
    j = Jitter(rng)
    b = SceneBuilder("derawar")
    X, Y = 100.0, 85.0
    pts = [(-X + 2 * X * k / 10, -Y) for k in range(10)]
    pts += [(X, -Y + 2 * Y * k / 9) for k in range(9)]
    pts += [(X - 2 * X * k / 10, Y) for k in range(10)]
    pts += [(-X, Y - 2 * Y * k / 9) for k in range(9)]
    radii = [j(6.0, 0.06) for _ in pts]
    for k, ((x, y), r) in enumerate(zip(pts, radii, strict=True)):
        b.add(bastion(center=(x, y, 0.0), radius=r, height=27.0 + j.shift(2.0)), ClassId.MINARET,
              f"bastion {k + 1}")
    for k in range(len(pts)):
        (xa, ya), (xb, yb) = pts[k], pts[(k + 1) % len(pts)]
        p = StraightPath(x0=xa, y0=ya, x1=xb, y1=yb)
        u0, u1 = 0.7 * radii[k], p.length - 0.7 * radii[(k + 1) % len(pts)]
        b.add(wall_panel(p, u0=u0, u1=u1, z0=0.0, z1=j(20.0, 0.02), thickness=4.0, caps=("top",)),
              ClassId.WALL, f"curtain wall {k + 1}")
    add_ground(b, -128.0, 128.0, -113.0, 113.0)
    add_clutter(b, j, [("tree", -115.0, -100.0, 0.0), ("tree", 118.0, 95.0, 0.0), ("tree", 20.0, 30.0, 0.0),
                       ("tree", -30.0, -20.0, 0.0), ("car", 112.0, -40.0, 1.5),
                       ("car", 10.0, -100.0, 0.0), ("bench", -5.0, 5.0, 0.0),
                       ("bicycle", 5.0, -98.0, 0.2)])
    add_stations(b, [(0.0, -110.0), (0.0, 110.0), (-124.0, 0.0), (124.0, 0.0), (0.0, 0.0),
                     (-122.0, -108.0), (122.0, 108.0), (-122.0, 108.0), (122.0, -108.0),
                     (-50.0, 30.0), (50.0, -30.0), (-60.0, -110.0), (60.0, 110.0)])
    return b.build()


# --------------------------------------------------------------------------- Roman
def roman(rng: RngLike = None) -> Scene:
    """A Colosseum-like curved facade: 3 storeys of 27 + 26 + 26 round arches; 20 x 36 x 14 m.

    The facade's centre line is a 190-degree arc of radius 17.4 m (wall 1.2 m thick),
    storeys 5.0, 4.5 and 4.5 m high, each an arcade of bays (arch span about 1.45 m,
    piers about 0.7 m) with a wall band (entablature) above; two gallery floor slabs
    behind the upper storeys.
    """
    j = Jitter(rng)
    b = SceneBuilder("roman")
    R, t = 17.4, 1.2
    cx = -8.2
    half = np.deg2rad(95.0)
    path = ArcPath(cx=cx, cy=0.0, radius=R, theta0=-half, theta1=half)
    L = path.length
    storeys = [(0.0, 5.0, 27, 1.45, 3.0), (5.0, 4.5, 26, 1.5, 2.6), (9.5, 4.5, 26, 1.5, 2.6)]
    for s, (z0, hgt, n, span, spring) in enumerate(storeys):
        pitch = L / n
        parts = arcade(path, n_bays=n, bay_width=pitch, span=j(span, 0.02), spring=j(spring, 0.02),
                       kind="round", height=hgt, thickness=t, z0=z0)
        add_arcade(b, parts, f"storey {s + 1} arcade")
    th = np.linspace(-half, half, 96)
    r_in, r_out = R - t / 2 - 3.0, R - t / 2
    ring = np.concatenate([np.c_[cx + r_out * np.cos(th), r_out * np.sin(th)],
                           np.c_[cx + r_in * np.cos(th[::-1]), r_in * np.sin(th[::-1])]])
    for k, z in enumerate((5.0, 9.5)):
        b.add(slab(ring, z0=z - 0.3, z1=z), ClassId.ROOF, f"gallery floor {k + 1}")
    add_ground(b, -32.0, 34.0, -40.0, 40.0)
    add_clutter(b, j, [("tree", 26.0, 26.0, 0.0), ("tree", -22.0, -32.0, 0.0), ("car", 28.0, -20.0, 0.7),
                       ("bench", -4.0, 8.0, 0.0), ("bicycle", 22.0, 5.0, 1.2)])
    add_stations(b, [(28.0, 0.0), (-6.0, 0.0), (18.0, 25.0), (18.0, -25.0), (-2.0, 33.0),
                     (-2.0, -33.0), (2.0, 10.0), (2.0, -10.0), (-20.0, 20.0), (-20.0, -20.0)])
    return b.build()


# --------------------------------------------------------------------------- Temple
def temple(rng: RngLike = None) -> Scene:
    """A temple: a 10 x 16 x 8 m block with a 7 x 10 x 4 m upper tier, 7 onion domes and
    4 slender 44 m minarets at the corners.

    Domes: one large on the upper tier, two medium at its ends, two small at the ends and
    two smaller at the sides of the lower roof.
    """
    j = Jitter(rng)
    b = SceneBuilder("temple")
    room(b, "lower", x0=-4.7, x1=4.7, y0=-7.7, y1=7.7, height=7.5, thickness=0.6)
    b.add(roof_slab(rect(-5.0, 5.0, -8.0, 8.0), z=8.0, thickness=0.5), ClassId.ROOF, "lower roof")
    room(b, "upper", x0=-3.3, x1=3.3, y0=-4.8, y1=4.8, height=12.0 - 0.4, thickness=0.4)
    b.add(roof_slab(rect(-3.5, 3.5, -5.0, 5.0), z=12.0, thickness=0.4), ClassId.ROOF, "upper roof")
    domes = [((0.0, 0.0, 12.0), j(2.3), 1.6, 1.6), ((0.0, -3.9, 12.0), j(0.95), 0.6, 0.8),
             ((0.0, 3.9, 12.0), j(0.95), 0.6, 0.8), ((0.0, -6.5, 8.0), j(0.85), 0.4, 0.7),
             ((0.0, 6.5, 8.0), j(0.85), 0.4, 0.7), ((-4.25, 0.0, 8.0), j(0.65), 0.3, 0.5),
             ((4.25, 0.0, 8.0), j(0.65), 0.3, 0.5)]
    for k, (c, r, dh, fin) in enumerate(domes):
        b.add(dome(center=c, kind="onion", radius=r, bulge=j(1.2, 0.02), drum_height=dh,
                   drum_thickness=0.3 * r, thickness=0.12 * r + 0.05, finial=fin),
              ClassId.DOME, f"dome {k + 1}")
    for x in (-4.0, 4.0):
        for y in (-7.0, 7.0):
            b.add(minaret(center=(x, y, 0.0), height=j(44.0, 0.01), base_radius=0.65, n_stages=5,
                          n_segments=24, balcony_depth=0.5, taper=0.04, setback=0.03,
                          parapet_height=0.9, plinth_height=1.0, n_posts=6),
                  ClassId.MINARET, f"minaret ({x:+.0f}, {y:+.0f})")
    add_ground(b, -30.0, 30.0, -28.0, 28.0)
    add_clutter(b, j, [("tree", -16.0, 18.0, 0.0), ("tree", 17.0, -19.0, 0.0), ("bench", 9.0, 12.0, 0.5),
                       ("car", -15.0, -18.0, 0.3), ("bicycle", 10.0, -12.0, 0.8)])
    add_stations(b, [(18.0, -14.0), (-18.0, 14.0), (26.0, 3.0), (-26.0, -3.0), (16.0, 18.0),
                     (-17.0, -18.0), (0.0, -24.0), (0.0, 24.0)])
    return b.build()
