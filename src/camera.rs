//! The render camera: generates primary rays in render space from film positions, and
//! provides the world-to-camera and world-to-NDC matrices compositors read from the EXR.

use crate::geometry::cone::RayCone;
use crate::geometry::ray::Ray;
use crate::geometry::space::RenderSpace;
use crate::sampling::warp::square_to_uniform_disk;
use crate::scene::{self, Projection};
use glam::{DMat4, DVec3, DVec4, Vec2, Vec3};

/// Image size used when neither the request nor the scene decides it: the long side.
pub const DEFAULT_LONG_SIDE: u32 = 512;
/// Longest image side lucerna renders.
pub const MAX_IMAGE_SIDE: u32 = 65536;

/// A camera in render space.
#[derive(Clone, Debug)]
pub struct Camera {
    origin: Vec3,
    right: Vec3,
    up: Vec3,
    forward: Vec3,
    kind: Kind,
    lens_radius: f32,
    focus_distance: f32,
    /// The image rendered, overscan included.
    width: u32,
    height: u32,
    /// The image without overscan, and the overscan around it.
    display: (u32, u32),
    overscan: Overscan,
    /// Film position (pixels of the image proper) to NDC scale: 2 / width, 2 / height.
    film_to_ndc: Vec2,
    /// World to camera space (x right, y up, z forward: OpenEXR's convention).
    pub world_to_camera: DMat4,
    /// World to OpenEXR NDC ((0, 0) top-left, (1, 1) bottom-right of the image).
    pub world_to_ndc: DMat4,
    /// Render-space length to world units (for the depth AOV).
    to_world_length: f32,
    /// Clipping range along the viewing axis, render space.
    clip_near: f32,
    clip_far: f32,
    /// Camera to render space over the shutter, where the camera moves: rays leave from
    /// where it is at their time ([`Camera::generate_ray_at`]).
    motion: Option<std::sync::Arc<crate::geometry::motion::MotionTransform>>,
}

/// Where a camera is and which way it looks (render space, unit axes).
struct Pose {
    origin: Vec3,
    right: Vec3,
    up: Vec3,
    forward: Vec3,
}

/// Pixels rendered beyond each edge of the image (overscan): the EXR's data window reaches
/// past its display window by these, so that a compositor's distortion, shake or blur has
/// picture to pull in from outside the frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Overscan {
    pub left: u32,
    pub top: u32,
    pub right: u32,
    pub bottom: u32,
}

/// The most pixels of overscan an edge may have.
pub const MAX_OVERSCAN: u32 = 16384;

impl Overscan {
    /// The same overscan on every edge.
    pub fn uniform(pixels: u32) -> Self {
        Self {
            left: pixels,
            top: pixels,
            right: pixels,
            bottom: pixels,
        }
    }

    /// Parses `N` (every edge) or `LEFT,TOP,RIGHT,BOTTOM`, in pixels.
    pub fn parse(text: &str) -> Result<Self, String> {
        let numbers: Vec<u32> = text
            .split(',')
            .map(|v| v.trim().parse::<u32>())
            .collect::<Result<_, _>>()
            .map_err(|_| format!("expected PIXELS or LEFT,TOP,RIGHT,BOTTOM, got {text:?}"))?;
        let overscan = match numbers[..] {
            [n] => Self::uniform(n),
            [left, top, right, bottom] => Self {
                left,
                top,
                right,
                bottom,
            },
            _ => {
                return Err(format!(
                    "expected PIXELS or LEFT,TOP,RIGHT,BOTTOM, got {text:?}"
                ));
            }
        };
        if overscan.edges().iter().any(|&e| e > MAX_OVERSCAN) {
            return Err(format!(
                "overscan {text:?}: at most {MAX_OVERSCAN} pixels an edge"
            ));
        }
        Ok(overscan)
    }

    /// `LEFT,TOP,RIGHT,BOTTOM`, as [`Overscan::parse`] reads it.
    pub fn describe(&self) -> String {
        let [l, t, r, b] = self.edges();
        format!("{l},{t},{r},{b}")
    }

    fn edges(&self) -> [u32; 4] {
        [self.left, self.top, self.right, self.bottom]
    }

    pub fn is_none(&self) -> bool {
        *self == Self::default()
    }

    /// The size rendered for an image of `width` × `height` with this overscan.
    pub fn extend(&self, (width, height): (u32, u32)) -> (u32, u32) {
        (
            width + self.left + self.right,
            height + self.top + self.bottom,
        )
    }

    /// The size of the image whose rendered size (with this overscan) is `size`.
    pub fn display(&self, (width, height): (u32, u32)) -> (u32, u32) {
        (
            width - self.left - self.right,
            height - self.top - self.bottom,
        )
    }
}

#[derive(Clone, Copy, Debug)]
enum Kind {
    Perspective { tan_half_x: f32, tan_half_y: f32 },
    Orthographic { half_width: f32, half_height: f32 },
}

/// The resolution for a render: the request's, else the camera's aspect ratio with
/// [`DEFAULT_LONG_SIDE`], else 4:3.
pub fn resolve_resolution(
    requested: Option<(u32, u32)>,
    camera: Option<&scene::Camera>,
) -> (u32, u32) {
    if let Some(r) = requested {
        return r;
    }
    let aspect = camera.and_then(|c| match c.projection {
        Projection::Perspective { aspect, .. } => aspect,
        Projection::Orthographic { xmag, ymag } => Some(xmag / ymag),
    });
    let aspect = aspect
        .filter(|a| a.is_finite() && *a > 0.0)
        .unwrap_or(4.0 / 3.0);
    let long = DEFAULT_LONG_SIDE as f32;
    if aspect >= 1.0 {
        (DEFAULT_LONG_SIDE, ((long / aspect).round() as u32).max(1))
    } else {
        (((long * aspect).round() as u32).max(1), DEFAULT_LONG_SIDE)
    }
}

/// A perspective camera framing world bounds `(lo, hi)`: looking along -Z at the bounds'
/// centre from far enough that the bounding sphere fills a 40° field of view.
pub fn framing_camera(lo: DVec3, hi: DVec3) -> scene::Camera {
    let yfov = 40f32.to_radians();
    let centre = (lo + hi) * 0.5;
    let radius = ((hi - lo).length() * 0.5).max(1e-9);
    let distance = radius / (yfov as f64 * 0.5).sin();
    scene::Camera {
        name: "auto".into(),
        projection: Projection::Perspective { yfov, aspect: None },
        transform: DMat4::from_translation(centre + DVec3::Z * distance),
        aperture_radius: 0.0,
        focus_distance: distance,
        clip_near: 0.0,
        clip_far: None,
        fit: Default::default(),
        motion: Vec::new(),
    }
}

/// The camera's aperture aspect where `fit` keeps the aperture's width instead of its height:
/// an image narrower than the aperture under [`CameraFit::ExpandAperture`].
fn expanded(fit: scene::CameraFit, aperture: Option<f32>, image: f32) -> Option<f32> {
    aperture.filter(|&a| {
        fit == scene::CameraFit::ExpandAperture && a.is_finite() && a > 0.0 && image < a
    })
}

impl Camera {
    /// The render camera for scene camera `c` at `width` × `height`. A perspective camera
    /// keeps its vertical field of view, an orthographic one its height, unless `c.fit`
    /// keeps the aperture's width for an image narrower than it.
    pub fn new(c: &scene::Camera, space: &RenderSpace, width: u32, height: u32) -> Self {
        let aspect = width as f32 / height as f32;
        let m = c.transform;
        let origin_w = m.transform_point3(DVec3::ZERO);
        let right_w = m.transform_vector3(DVec3::X).normalize();
        let forward_w = (-m.transform_vector3(DVec3::Z)).normalize();
        // Re-orthogonalise: a sheared or scaled node must not skew the view.
        let up_w = right_w.cross(forward_w).normalize();
        let right_w = forward_w.cross(up_w);
        let kind = match c.projection {
            Projection::Perspective {
                yfov,
                aspect: aperture,
            } => {
                let mut tan_half_y = (yfov * 0.5).tan();
                if let Some(aperture) = expanded(c.fit, aperture, aspect) {
                    tan_half_y *= aperture / aspect;
                }
                Kind::Perspective {
                    tan_half_x: tan_half_y * aspect,
                    tan_half_y,
                }
            }
            Projection::Orthographic { xmag, ymag } => {
                let ymag = match expanded(c.fit, Some(xmag / ymag), aspect) {
                    Some(_) => xmag / aspect,
                    None => ymag,
                };
                Kind::Orthographic {
                    half_width: ymag * aspect * space.scale as f32,
                    half_height: ymag * space.scale as f32,
                }
            }
        };
        let camera_to_world = DMat4::from_cols(
            right_w.extend(0.0),
            up_w.extend(0.0),
            forward_w.extend(0.0),
            origin_w.extend(1.0),
        );
        let world_to_camera = camera_to_world.inverse();
        let projection = match kind {
            Kind::Perspective {
                tan_half_x,
                tan_half_y,
            } => DMat4::from_cols(
                DVec4::new(0.5 / tan_half_x as f64, 0.0, 0.0, 0.0),
                DVec4::new(0.0, -0.5 / tan_half_y as f64, 0.0, 0.0),
                DVec4::new(0.5, 0.5, 0.0, 1.0),
                // z_ndc = 1 / z: invertible, and the reversed depth Nuke's renderer writes.
                DVec4::new(0.0, 0.0, 1.0, 0.0),
            ),
            Kind::Orthographic {
                half_width,
                half_height,
            } => {
                let (hw, hh) = (
                    half_width as f64 / space.scale,
                    half_height as f64 / space.scale,
                );
                DMat4::from_cols(
                    DVec4::new(0.5 / hw, 0.0, 0.0, 0.0),
                    DVec4::new(0.0, -0.5 / hh, 0.0, 0.0),
                    DVec4::new(0.0, 0.0, 1.0, 0.0),
                    DVec4::new(0.5, 0.5, 0.0, 1.0),
                )
            }
        };
        Self {
            origin: space.point(origin_w),
            right: right_w.as_vec3(),
            up: up_w.as_vec3(),
            forward: forward_w.as_vec3(),
            kind,
            lens_radius: (c.aperture_radius * space.scale) as f32,
            focus_distance: (c.focus_distance * space.scale) as f32,
            width,
            height,
            display: (width, height),
            overscan: Overscan::default(),
            film_to_ndc: Vec2::new(2.0 / width as f32, 2.0 / height as f32),
            world_to_camera,
            world_to_ndc: projection * world_to_camera,
            to_world_length: (1.0 / space.scale) as f32,
            clip_near: (c.clip_near.max(0.0) * space.scale) as f32,
            clip_far: c
                .clip_far
                .map_or(f32::INFINITY, |f| (f * space.scale) as f32),
            motion: crate::geometry::motion::keys_move(&c.motion)
                .then(|| {
                    let keys: Vec<DMat4> = c.motion.iter().map(|k| space.matrix() * *k).collect();
                    crate::geometry::motion::MotionTransform::new(&keys)
                })
                .flatten()
                .map(std::sync::Arc::new),
        }
    }

    /// True if the camera moves while the shutter is open.
    pub fn moves(&self) -> bool {
        self.motion.is_some()
    }

    /// [`Camera::generate_ray`] at shutter time `time`: from where a moving camera is then
    /// (its frame's axes made orthonormal, as [`Camera::new`] makes them).
    #[inline]
    pub fn generate_ray_at(&self, film: Vec2, lens: Vec2, time: f32) -> Ray {
        if self.motion.is_none() {
            return self.generate_ray(film, lens).at_time(time);
        }
        self.ray_from(&self.pose_at(time), film, lens).at_time(time)
    }

    /// Where the camera is at shutter time `time`.
    fn pose_at(&self, time: f32) -> Pose {
        let Some(motion) = &self.motion else {
            return Pose {
                origin: self.origin,
                right: self.right,
                up: self.up,
                forward: self.forward,
            };
        };
        // Once per camera sample: the single-precision interpolation traversal uses.
        let m = motion.affine_at(time);
        let right = m.transform_vector3(Vec3::X).normalize();
        let forward = (-m.transform_vector3(Vec3::Z)).normalize();
        let up = right.cross(forward).normalize();
        Pose {
            origin: m.translation.into(),
            right: forward.cross(up),
            up,
            forward,
        }
    }

    /// The film position (pixels of the image proper, as [`Camera::generate_ray`] takes
    /// them) where render-space point `p` appears at shutter time `time`, through the
    /// lens's centre; `None` for a point at or behind a perspective camera's plane.
    pub fn film_position_at(&self, p: Vec3, time: f32) -> Option<Vec2> {
        let pose = self.pose_at(time);
        let d = p - pose.origin;
        let (x, y, z) = (d.dot(pose.right), d.dot(pose.up), d.dot(pose.forward));
        let ndc = match self.kind {
            Kind::Perspective {
                tan_half_x,
                tan_half_y,
            } => {
                if !(z > 0.0) {
                    return None;
                }
                Vec2::new(x / (z * tan_half_x), y / (z * tan_half_y))
            }
            Kind::Orthographic {
                half_width,
                half_height,
            } => Vec2::new(x / half_width, y / half_height),
        };
        Some(Vec2::new(
            (ndc.x + 1.0) / self.film_to_ndc.x,
            (1.0 - ndc.y) / self.film_to_ndc.y,
        ))
    }

    /// The camera rendering `overscan` pixels beyond the edges of its image as well: the
    /// image it renders grows by them, its view of the image inside stays the same (every
    /// pixel keeps its ray), and its EXR's data window reaches past the display window.
    pub fn overscanned(mut self, overscan: Overscan) -> Self {
        (self.width, self.height) = overscan.extend(self.display);
        self.overscan = overscan;
        self
    }

    /// Pixel (`x`, `y`) of the image rendered in the coordinates of the image proper
    /// (negative left of and above it, in the overscan): where its rays go
    /// ([`Camera::generate_ray`]) and which samples it takes, so that a pixel renders the
    /// same whatever the overscan.
    #[inline]
    pub fn image_pixel(&self, x: u32, y: u32) -> (i32, i32) {
        (
            x.wrapping_sub(self.overscan.left) as i32,
            y.wrapping_sub(self.overscan.top) as i32,
        )
    }

    /// The image without its overscan (the EXR's display window).
    pub fn display(&self) -> (u32, u32) {
        self.display
    }

    /// Pixels rendered beyond each edge of the image.
    pub fn overscan(&self) -> Overscan {
        self.overscan
    }

    /// Width in pixels of the image rendered (overscan included).
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels of the image rendered (overscan included).
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Where the camera is (render space): the pinhole, or the centre of the lens or of an
    /// orthographic view.
    pub fn origin(&self) -> Vec3 {
        self.origin
    }

    /// The primary ray through film position `film` (pixels of the image proper, (0, 0) =
    /// its top-left corner, negative in the overscan left of and above it),
    /// with lens sample `lens` for depth of field, limited to the clipping range. The
    /// direction is unit length.
    #[inline]
    pub fn generate_ray(&self, film: Vec2, lens: Vec2) -> Ray {
        let pose = Pose {
            origin: self.origin,
            right: self.right,
            up: self.up,
            forward: self.forward,
        };
        self.ray_from(&pose, film, lens)
    }

    /// [`Camera::generate_ray`] from the camera at `pose`.
    #[inline(always)]
    fn ray_from(&self, pose: &Pose, film: Vec2, lens: Vec2) -> Ray {
        let to_world = |v: Vec3| pose.right * v.x + pose.up * v.y + pose.forward * v.z;
        let ndc = Vec2::new(
            film.x * self.film_to_ndc.x - 1.0,
            1.0 - film.y * self.film_to_ndc.y,
        );
        // Camera-space directions are scaled to z = 1: one unit along the viewing axis.
        let (origin_cam, dir_cam) = match self.kind {
            Kind::Perspective {
                tan_half_x,
                tan_half_y,
            } => {
                let dir = Vec3::new(ndc.x * tan_half_x, ndc.y * tan_half_y, 1.0);
                if self.lens_radius > 0.0 {
                    let l = square_to_uniform_disk(lens) * self.lens_radius;
                    let o = Vec3::new(l.x, l.y, 0.0);
                    // Towards the pinhole ray's point in focus (dir × focus distance), scaled
                    // to z = 1.
                    (o, dir - o / self.focus_distance)
                } else {
                    (Vec3::ZERO, dir)
                }
            }
            Kind::Orthographic {
                half_width,
                half_height,
            } => (
                Vec3::new(ndc.x * half_width, ndc.y * half_height, 0.0),
                Vec3::Z,
            ),
        };
        let length = dir_cam.length();
        let dir = to_world(dir_cam) * length.recip();
        // Clipping distances are along the viewing axis: as dir_cam.z = 1, a unit of ray
        // distance covers 1 / length of it.
        let (near, far) = (self.clip_near * length, self.clip_far * length);
        Ray {
            origin: pose.origin + to_world(origin_cam) + dir * near,
            dir,
            tmax: far - near,
            time: 0.0,
        }
    }

    /// The cone of a primary ray through one pixel: a perspective camera's spreads by the
    /// angle a pixel spans at the image centre; an orthographic camera's is as wide as a
    /// pixel and does not spread.
    pub fn pixel_cone(&self) -> RayCone {
        match self.kind {
            Kind::Perspective { tan_half_y, .. } => RayCone {
                width: 0.0,
                spread: 2.0 * tan_half_y / self.display.1 as f32,
            },
            Kind::Orthographic { half_height, .. } => RayCone {
                width: 2.0 * half_height / self.display.1 as f32,
                spread: 0.0,
            },
        }
    }

    /// Camera-space vector `v` in render space (without the camera's position).
    #[inline]
    fn to_world(&self, v: Vec3) -> Vec3 {
        self.right * v.x + self.up * v.y + self.forward * v.z
    }

    /// A pinhole perspective camera's primary rays through film positions `(x, y)` in
    /// eight lanes: [`Camera::generate_ray`]'s operations lane by lane, so each lane's ray
    /// is the scalar one to the bit (origins, unit directions, ray lengths). `None` for
    /// other cameras, whose rays the scalar code generates. Only for code compiled with
    /// AVX2 (see `crate::simd`).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(crate) fn pinhole_rays_lanes(
        &self,
        x: crate::simd::F8,
        y: crate::simd::F8,
    ) -> Option<(crate::simd::V3, crate::simd::V3, crate::simd::F8)> {
        use crate::simd::{F8, V3};
        let Kind::Perspective {
            tan_half_x,
            tan_half_y,
        } = self.kind
        else {
            return None;
        };
        if self.lens_radius > 0.0 {
            return None;
        }
        let one = F8::ONE;
        let ndc_x = x * self.film_to_ndc.x - one;
        let ndc_y = one - y * self.film_to_ndc.y;
        let (dx, dy) = (ndc_x * tan_half_x, ndc_y * tan_half_y);
        let world =
            V3::splat(self.right) * dx + V3::splat(self.up) * dy + V3::splat(self.forward) * one;
        let length = (dx * dx + dy * dy + one * one).sqrt();
        let dir = world * (one / length);
        let (near, far) = (length * self.clip_near, length * self.clip_far);
        // The scalar code adds the lens offset (zero) in camera space to the origin first.
        let origin = V3::splat(self.origin + self.to_world(Vec3::ZERO)) + dir * near;
        Some((origin, dir, far - near))
    }

    /// Distance of render-space point `p` along the viewing axis, in world units (the
    /// depth AOV's Z).
    #[inline]
    pub fn depth(&self, p: Vec3) -> f32 {
        (p - self.origin).dot(self.forward) * self.to_world_length
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera at (1, 2, 3) turned about two axes, in a render space that moves and scales.
    fn camera(projection: Projection, aperture_radius: f64) -> Camera {
        let c = scene::Camera {
            name: "test".into(),
            projection,
            transform: DMat4::from_translation(DVec3::new(1.0, 2.0, 3.0))
                * DMat4::from_rotation_y(0.4)
                * DMat4::from_rotation_x(-0.3),
            aperture_radius,
            focus_distance: 5.0,
            clip_near: 0.5,
            clip_far: Some(20.0),
            fit: Default::default(),
            motion: Vec::new(),
        };
        let space = RenderSpace::from_bounds(DVec3::splat(-4.0), DVec3::splat(6.0));
        Camera::new(&c, &space, 64, 48)
    }

    /// A pinhole camera's rays in lanes are the scalar rays to the bit, over the film and
    /// at its edges; other cameras leave their rays to the scalar code.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn pinhole_lanes_are_the_scalar_rays() {
        use crate::simd::F8;
        if !crate::simd::avx2_or_skip() {
            return;
        }
        let perspective = Projection::Perspective {
            yfov: 0.8,
            aspect: None,
        };
        let cam = camera(perspective.clone(), 0.0);
        let mut rng = crate::sampling::pcg::Pcg32::new(5, 1);
        for round in 0..2_000 {
            let film: [Vec2; 8] = std::array::from_fn(|l| match (round + l) % 4 {
                0 => Vec2::new(0.0, 48.0 * rng.next_f32()),
                1 => Vec2::new(64.0 * rng.next_f32(), 48.0),
                _ => Vec2::new(64.0 * rng.next_f32(), 48.0 * rng.next_f32()),
            });
            let (x, y) = (film.map(|f| f.x), film.map(|f| f.y));
            let (origin, dir, tmax) = cam
                .pinhole_rays_lanes(F8::from_array(x), F8::from_array(y))
                .expect("a pinhole camera");
            for (l, &f) in film.iter().enumerate() {
                let ray = cam.generate_ray(f, Vec2::splat(0.5));
                let bits = |v: Vec3| v.to_array().map(f32::to_bits);
                assert_eq!(bits(origin.lane(l)), bits(ray.origin), "film {f}");
                assert_eq!(bits(dir.lane(l)), bits(ray.dir), "film {f}");
                assert_eq!(tmax.to_array()[l].to_bits(), ray.tmax.to_bits(), "film {f}");
            }
        }
        let orthographic = Projection::Orthographic {
            xmag: 2.0,
            ymag: 1.5,
        };
        for cam in [camera(perspective, 0.3), camera(orthographic, 0.0)] {
            assert!(cam.pinhole_rays_lanes(F8::ONE, F8::ONE).is_none());
        }
    }

    /// Every ray has a unit direction, starts on the near clipping plane and ends on the far
    /// one (distances along the viewing axis); with a lens, all rays through a film point
    /// meet on the plane in focus, at the pinhole ray's point there.
    #[test]
    fn rays_span_the_clipping_range_and_meet_in_focus() {
        let perspective = Projection::Perspective {
            yfov: 0.8,
            aspect: None,
        };
        let orthographic = Projection::Orthographic {
            xmag: 2.0,
            ymag: 1.5,
        };
        let film = [(0.0, 0.0), (63.9, 47.9), (10.3, 40.1), (32.0, 24.0)];
        let lens = [(0.1, 0.9), (0.5, 0.5), (0.99, 0.02)];
        for (projection, aperture) in [
            (perspective.clone(), 0.0),
            (perspective, 0.3),
            (orthographic, 0.0),
        ] {
            let cam = camera(projection, aperture);
            // World units, as the scene camera's.
            let (near, far, focus) = (0.5, 20.0, 5.0);
            for &(fx, fy) in &film {
                let film = Vec2::new(fx, fy);
                let pinhole = cam.generate_ray(film, Vec2::splat(0.5));
                for &(lx, ly) in &lens {
                    let ray = cam.generate_ray(film, Vec2::new(lx, ly));
                    let end = ray.origin + ray.dir * ray.tmax;
                    assert!((ray.dir.length() - 1.0).abs() < 1e-6, "{ray:?}");
                    assert!((cam.depth(ray.origin) - near).abs() < 1e-5 * far, "{ray:?}");
                    assert!((cam.depth(end) - far).abs() < 1e-5 * far, "{ray:?}");
                    if aperture > 0.0 {
                        let in_focus = |r: &Ray| {
                            let start = cam.depth(r.origin);
                            let per_unit = cam.depth(r.origin + r.dir) - start;
                            r.origin + r.dir * ((focus - start) / per_unit)
                        };
                        let miss = (in_focus(&ray) - in_focus(&pinhole)) * cam.to_world_length;
                        assert!(miss.length() < 1e-5 * far, "{ray:?}: {miss}");
                    }
                }
            }
        }
    }

    #[test]
    fn overscan_grows_the_image_and_keeps_its_pixels() {
        let plain = camera(
            Projection::Perspective {
                yfov: 0.8,
                aspect: None,
            },
            0.0,
        );
        let o = Overscan::parse("3,1,4,2").unwrap();
        let wide = plain.clone().overscanned(o);
        assert_eq!((wide.width(), wide.height()), (71, 51));
        assert_eq!(wide.display(), (64, 48));
        // Rendered pixel (3, 1) is the image's (0, 0), the first pixel (-3, -1) beyond it.
        assert_eq!(wide.image_pixel(3, 1), (0, 0));
        assert_eq!(wide.image_pixel(0, 0), (-3, -1));
        assert_eq!(wide.pixel_cone().spread, plain.pixel_cone().spread);
        assert_eq!(wide.world_to_ndc, plain.world_to_ndc);
        assert_eq!(Overscan::parse("5").unwrap(), Overscan::uniform(5));
        assert_eq!(Overscan::parse(&o.describe()).unwrap(), o);
        for bad in ["", "1,2", "-1", "1,2,3,4,5", "16385"] {
            assert!(Overscan::parse(bad).is_err(), "{bad:?}");
        }
    }
}
