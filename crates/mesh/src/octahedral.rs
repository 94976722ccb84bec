//! Octahedral impostor frames: the view directions of a `frames × frames` grid laid on an
//! octahedron (the full sphere) or a hemi-octahedron (the upper half, for things seen from
//! above the ground), and for any view direction the three frames an impostor blends with their
//! weights. The reference that `shaders/impostor.wgsl` mirrors line for line (a GPU test runs
//! both on the same directions).
//!
//! Conventions: +Y is up; a direction is where the camera looks *from* (object to eye). The grid
//! holds frames at its points, `u = i / (frames − 1)`, `v = j / (frames − 1)` (frame number
//! `j · frames + i`), so the poles and the horizon are frames of their own, as in Ryan Brucks'
//! impostor baker and Amplify Impostors. A direction's grid cell is split into two triangles
//! along its anti-diagonal (on the full octahedron, in the two quadrants where the equator runs
//! the other way, along its main diagonal, so that no triangle straddles the equator); the
//! frames at the corners of the triangle that holds the direction blend with its
//! barycentric weights, so the weights are continuous across cells and a frame's weight is 1 at
//! its own direction.

use glam::{Vec2, Vec3};

/// Which part of the sphere the frames cover.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum Sphere {
    /// The upper hemisphere (y ≥ 0): the grid's square is the hemi-octahedron (its diagonals
    /// are the x and z axes); views from below use the horizon's frames.
    Hemi,
    /// The whole sphere: the grid's square is the octahedron unfolded (lower half folded out to
    /// the corners).
    Full,
}

/// A grid of impostor frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct FrameGrid {
    /// Frames along each side (at least 2).
    pub frames: u32,
    pub sphere: Sphere,
}

/// The point in the unit square, `[0, 1]²`, of the direction `direction` (need not be unit
/// length; zero maps to straight up).
pub fn encode(direction: Vec3, sphere: Sphere) -> Vec2 {
    let direction = match sphere {
        Sphere::Hemi => Vec3::new(direction.x, direction.y.max(0.0), direction.z),
        Sphere::Full => direction,
    };
    let sum = direction.x.abs() + direction.y.abs() + direction.z.abs();
    if sum <= 0.0 {
        return Vec2::splat(0.5);
    }
    let d = direction / sum;
    let square = match sphere {
        Sphere::Hemi => Vec2::new(d.x + d.z, d.x - d.z),
        Sphere::Full if d.y >= 0.0 => Vec2::new(d.x, d.z),
        Sphere::Full => Vec2::new((1.0 - d.z.abs()) * sign(d.x), (1.0 - d.x.abs()) * sign(d.z)),
    };
    (square * 0.5 + 0.5).clamp(Vec2::ZERO, Vec2::ONE)
}

/// The unit direction of the point `uv` of the unit square ([`encode`]'s inverse).
pub fn decode(uv: Vec2, sphere: Sphere) -> Vec3 {
    let square = uv.clamp(Vec2::ZERO, Vec2::ONE) * 2.0 - 1.0;
    let direction = match sphere {
        Sphere::Hemi => {
            let (x, z) = (0.5 * (square.x + square.y), 0.5 * (square.x - square.y));
            Vec3::new(x, 1.0 - x.abs() - z.abs(), z)
        }
        Sphere::Full => {
            let y = 1.0 - square.x.abs() - square.y.abs();
            if y >= 0.0 {
                Vec3::new(square.x, y, square.y)
            } else {
                let (x, z) = (square.x, square.y);
                Vec3::new((1.0 - z.abs()) * sign(x), y, (1.0 - x.abs()) * sign(z))
            }
        }
    };
    direction.normalize()
}

/// `1` for 0 and above, `-1` below (WGSL's `select(-1.0, 1.0, x >= 0.0)`, not `sign`, which is 0
/// at 0).
fn sign(value: f32) -> f32 {
    if value >= 0.0 {
        1.0
    } else {
        -1.0
    }
}

impl FrameGrid {
    /// `frames` a side on the hemi-octahedron (`hemi`) or the full one.
    pub fn new(frames: u32, hemi: bool) -> FrameGrid {
        FrameGrid { frames, sphere: if hemi { Sphere::Hemi } else { Sphere::Full } }
    }

    /// Whether the grid covers the upper half of the sphere only.
    pub fn is_hemi(self) -> bool {
        self.sphere == Sphere::Hemi
    }

    /// The number of frames.
    pub fn frame_count(self) -> u32 {
        self.frames * self.frames
    }

    /// The direction frame `frame` is rendered from.
    pub fn frame_direction(self, frame: u32) -> Vec3 {
        let last = (self.frames - 1) as f32;
        let (i, j) = (frame % self.frames, frame / self.frames);
        decode(Vec2::new(i as f32 / last, j as f32 / last), self.sphere)
    }

    /// The three frames an impostor seen from `direction` blends, each with its weight (the
    /// weights sum to 1; a frame seen from its own direction has weight 1).
    pub fn blend(self, direction: Vec3) -> [(u32, f32); 3] {
        let last = (self.frames - 1) as f32;
        let grid = encode(direction, self.sphere) * last;
        let cell = grid.floor().min(Vec2::splat(last - 1.0));
        let fraction = grid - cell;
        let (i, j) = (cell.x as u32, cell.y as u32);
        let frame = |di: u32, dj: u32| (j + dj) * self.frames + i + di;
        // On the full octahedron the equator crosses the square's quadrants along one diagonal
        // or the other: cells are split along the equator's direction, so that no triangle
        // blends a frame from above it with one from below it where the equator runs between.
        let centre = (cell + 0.5) / last - 0.5;
        if self.sphere == Sphere::Full && centre.x * centre.y < 0.0 {
            return if fraction.x >= fraction.y {
                [(frame(0, 0), 1.0 - fraction.x), (frame(1, 0), fraction.x - fraction.y), (frame(1, 1), fraction.y)]
            } else {
                [(frame(0, 0), 1.0 - fraction.y), (frame(0, 1), fraction.y - fraction.x), (frame(1, 1), fraction.x)]
            };
        }
        if fraction.x + fraction.y <= 1.0 {
            [(frame(0, 0), 1.0 - fraction.x - fraction.y), (frame(1, 0), fraction.x), (frame(0, 1), fraction.y)]
        } else {
            [
                (frame(1, 1), fraction.x + fraction.y - 1.0),
                (frame(1, 0), 1.0 - fraction.y),
                (frame(0, 1), 1.0 - fraction.x),
            ]
        }
    }
}

/// The image axes of the frame seen from `direction` (unit length, object to eye): `right` and
/// `up` in world space, a right-handed camera looking along `−direction` with world +Y up (−Z
/// up for a view from within 0.1° of straight above or below, where +Y is no guide).
pub fn frame_axes(direction: Vec3) -> (Vec3, Vec3) {
    let forward = -direction.normalize();
    let hint = if direction.normalize().y.abs() > 0.999_998 { Vec3::NEG_Z } else { Vec3::Y };
    let right = forward.cross(hint).normalize();
    (right, right.cross(forward))
}

/// The orthographic camera of the frame seen from `direction`: the bounding sphere (`center`,
/// `radius`) fills the frame, and depth runs from 0 at the sphere's near side to 1 at its far
/// side (WebGPU's clip depth).
pub fn frame_view_projection(center: Vec3, radius: f32, direction: Vec3) -> glam::Mat4 {
    frame_rect_view_projection(center, radius, direction, FULL_FRAME)
}

/// The bounding sphere's square as the eight points of an impostor's hull (`impostor::
/// view_hull`; the last ones repeated), in the view's axes in units of the radius: what an
/// impostor without a fitted hull is drawn as.
pub const SQUARE_HULL: [[f32; 2]; 8] =
    [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0]];

/// The whole of a frame's image: `[u0, v0, u1, v1]` of [`frame_rect_view_projection`].
pub const FULL_FRAME: [f32; 4] = [0.0, 0.0, 1.0, 1.0];

/// The orthographic camera of the part `rect` = `[u0, v0, u1, v1]` of the frame seen from
/// `direction`: `u` runs along the frame's right and `v` down its up axis, 0 to 1 across the
/// sphere (`u = dot(p − center, right) / 2r + ½`, `v = ½ − dot(p − center, up) / 2r`); depth
/// runs across the sphere as in [`frame_view_projection`].
pub fn frame_rect_view_projection(center: Vec3, radius: f32, direction: Vec3, rect: [f32; 4]) -> glam::Mat4 {
    let radius = radius.max(1e-6);
    // Looking at the centre with the frame's up, the camera's right is the frame's right.
    let (_, up) = frame_axes(direction);
    let view = glam::camera::rh::view::look_at_mat4(center + direction.normalize() * 2.0 * radius, center, up);
    let [u0, v0, u1, v1] = rect;
    let (left, right) = ((2.0 * u0 - 1.0) * radius, (2.0 * u1 - 1.0) * radius);
    let (bottom, top) = ((1.0 - 2.0 * v1) * radius, (1.0 - 2.0 * v0) * radius);
    let projection = glam::camera::rh::proj::directx::orthographic(left, right, bottom, top, radius, 3.0 * radius);
    projection * view
}
