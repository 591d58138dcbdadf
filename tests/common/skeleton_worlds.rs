//! Hand-made occupancy worlds for the skeleton tests (`tests/skeleton.rs`) and benchmark
//! (`benches/skeleton.rs`). Included with `#[path]`, not through `common/mod.rs`.
#![allow(dead_code)]

use nalgebra::Point3;
use topoloc::skeleton::OccupancyGrid;

/// Builds a grid by filling axis-aligned boxes (metres, world frame with the origin at the
/// grid's corner): a voxel belongs to a box when its centre is inside it.
pub struct World {
    dims: [usize; 3],
    voxel: f64,
    occupied: Vec<bool>,
}

impl World {
    /// A world of `size` metres at `voxel` metres, every voxel `occupied` or free.
    pub fn new(size: [f64; 3], voxel: f64, occupied: bool) -> Self {
        let dims = size.map(|s| (s / voxel).round() as usize);
        Self {
            dims,
            voxel,
            occupied: vec![occupied; dims[0] * dims[1] * dims[2]],
        }
    }

    /// Sets the voxels whose centre lies in the box `lo`-`hi`.
    pub fn fill(&mut self, lo: [f64; 3], hi: [f64; 3], occupied: bool) -> &mut Self {
        let range = |k: usize| {
            let first = ((lo[k] / self.voxel - 0.5).ceil().max(0.0)) as usize;
            let end = ((hi[k] / self.voxel - 0.5).ceil().max(0.0) as usize).min(self.dims[k]);
            first..end
        };
        let [nx, ny, _] = self.dims;
        for z in range(2) {
            for y in range(1) {
                for x in range(0) {
                    self.occupied[x + nx * (y + ny * z)] = occupied;
                }
            }
        }
        self
    }

    /// Frees the box `[x0, y0, x1, y1]` over the full height.
    pub fn carve(&mut self, r: [f64; 4]) -> &mut Self {
        let top = self.dims[2] as f64 * self.voxel;
        self.fill([r[0], r[1], 0.0], [r[2], r[3], top], false)
    }

    pub fn grid(&self) -> OccupancyGrid {
        OccupancyGrid::new(
            self.dims,
            self.voxel,
            Point3::origin(),
            self.occupied.clone(),
        )
        .expect("valid world")
    }
}

/// Solid rock of `size` (x, y) metres and `height` metres with the rectangles `rooms`
/// (`[x0, y0, x1, y1]`, metres) carved out over the full height.
pub fn carved(size: [f64; 2], height: f64, voxel: f64, rooms: &[[f64; 4]]) -> OccupancyGrid {
    let mut w = World::new([size[0], size[1], height], voxel, true);
    for &r in rooms {
        w.carve(r);
    }
    w.grid()
}

/// A straight corridor 6 m long and 1.2 m wide, 2 m high.
pub fn corridor(voxel: f64) -> OccupancyGrid {
    carved([8.0, 3.0], 2.0, voxel, &[[1.0, 1.0, 7.0, 2.2]])
}

/// An L: 6 m along x, then 6 m along y, 1.2 m wide.
pub fn l_corridor(voxel: f64) -> OccupancyGrid {
    carved(
        [8.0, 8.0],
        2.0,
        voxel,
        &[[1.0, 1.0, 7.0, 2.2], [5.8, 1.0, 7.0, 7.0]],
    )
}

/// A T: a 7 m corridor along x with a 5 m stem along y from its middle.
pub fn t_junction(voxel: f64) -> OccupancyGrid {
    carved(
        [9.0, 7.0],
        2.0,
        voxel,
        &[[1.0, 1.0, 8.0, 2.2], [3.9, 1.0, 5.1, 6.0]],
    )
}

/// A rectangular ring corridor 7 m x 5 m (outer), 1.2 m wide, around a solid block.
pub fn ring(voxel: f64) -> OccupancyGrid {
    carved(
        [9.0, 7.0],
        2.0,
        voxel,
        &[
            [1.0, 1.0, 8.0, 2.2],
            [1.0, 4.8, 8.0, 6.0],
            [1.0, 1.0, 2.2, 6.0],
            [6.8, 1.0, 8.0, 6.0],
        ],
    )
}

/// Two rooms of 4.9 m x 6 m, 2.4 m high, on either side of a 0.2 m wall, joined by a door
/// 1 m wide and 2 m high; floor and ceiling are occupied layers.
pub fn two_rooms(voxel: f64) -> OccupancyGrid {
    let mut w = World::new([11.0, 7.0, 2.8], voxel, true);
    w.fill([0.5, 0.5, 0.2], [5.4, 6.5, 2.6], false)
        .fill([5.6, 0.5, 0.2], [10.5, 6.5, 2.6], false)
        // the door through the wall x in [5.4, 5.6]
        .fill([5.3, 3.0, 0.2], [5.7, 4.0, 2.2], false);
    w.grid()
}

/// A small deterministic generator (64-bit LCG) for the office world.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A 40 m x 30 m x 3 m office floor at `voxel` metres: an outer wall, floor and ceiling slabs, a
/// 2.4 m corridor along x in the middle and a 2 m corridor along y, eight rooms per side
/// (0.2 m walls) each with a 1 m x 2.1 m door to the corridor and every other room with a door
/// to its neighbour (loops), pillars in the corridors and furniture boxes in the rooms.
pub fn office(voxel: f64) -> OccupancyGrid {
    let (sx, sy, sz) = (40.0, 30.0, 3.0);
    let mut w = World::new([sx, sy, sz], voxel, false);
    let mut rng = Lcg(0x5EED);
    // Floor, ceiling and outer walls.
    w.fill([0.0, 0.0, 0.0], [sx, sy, 0.2], true)
        .fill([0.0, 0.0, sz - 0.2], [sx, sy, sz], true)
        .fill([0.0, 0.0, 0.0], [0.2, sy, sz], true)
        .fill([sx - 0.2, 0.0, 0.0], [sx, sy, sz], true)
        .fill([0.0, 0.0, 0.0], [sx, 0.2, sz], true)
        .fill([0.0, sy - 0.2, 0.0], [sx, sy, sz], true);
    let (cy0, cy1) = (13.8, 16.2); // corridor along x
    let (cx0, cx1) = (19.0, 21.0); // corridor along y
                                   // Corridor walls, interrupted by the y corridor.
    for (y0, y1) in [(cy0 - 0.2, cy0), (cy1, cy1 + 0.2)] {
        w.fill([0.0, y0, 0.0], [cx0, y1, sz], true);
        w.fill([cx1, y0, 0.0], [sx, y1, sz], true);
    }
    for (x0, x1) in [(cx0 - 0.2, cx0), (cx1, cx1 + 0.2)] {
        w.fill([x0, 0.0, 0.0], [x1, cy0, sz], true);
        w.fill([x0, cy1, 0.0], [x1, sy, sz], true);
    }
    // Rooms: four per quadrant along x, separated by walls, each with a door to the corridor.
    for (x_start, x_end) in [(0.2, cx0 - 0.2), (cx1 + 0.2, sx - 0.2)] {
        let width = (x_end - x_start) / 4.0;
        for side in 0..2 {
            let (door_y0, door_y1) = if side == 0 {
                (cy0 - 0.3, cy0 + 0.1)
            } else {
                (cy1 - 0.1, cy1 + 0.3)
            };
            let (room_y0, room_y1) = if side == 0 {
                (0.2, cy0 - 0.2)
            } else {
                (cy1 + 0.2, sy - 0.2)
            };
            for r in 0..4 {
                let x0 = x_start + r as f64 * width;
                if r > 0 {
                    w.fill([x0 - 0.1, room_y0, 0.0], [x0 + 0.1, room_y1, sz], true);
                    if r % 2 == 1 {
                        // A door to the previous room, halfway in depth.
                        let y = 0.5 * (room_y0 + room_y1);
                        w.fill([x0 - 0.2, y - 0.5, 0.2], [x0 + 0.2, y + 0.5, 2.3], false);
                    }
                }
                let door_x = x0 + 0.3 * width + 0.4 * width * rng.next();
                w.fill(
                    [door_x - 0.5, door_y0, 0.2],
                    [door_x + 0.5, door_y1, 2.3],
                    false,
                );
                // Two desks and a cabinet.
                for _ in 0..2 {
                    let fx = x0 + 0.8 + (width - 2.6) * rng.next();
                    let fy = room_y0 + 1.0 + (room_y1 - room_y0 - 3.0) * rng.next();
                    w.fill([fx, fy, 0.2], [fx + 1.6, fy + 0.8, 0.95], true);
                }
                let cab_y = if side == 0 { room_y0 } else { room_y1 - 0.5 };
                w.fill([x0 + 0.3, cab_y, 0.2], [x0 + 1.3, cab_y + 0.5, 2.0], true);
            }
        }
    }
    // Pillars in the x corridor.
    for k in 0..5 {
        let px = 3.0 + 8.0 * k as f64;
        if (px - 20.0).abs() > 2.0 {
            w.fill([px, 14.8, 0.0], [px + 0.4, 15.2, sz], true);
        }
    }
    w.grid()
}
