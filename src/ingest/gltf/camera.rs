//! Cameras: perspective and orthographic, placed by their node.

use super::Importer;
use crate::error::Result;
use crate::scene::{Camera, Projection};
use glam::DMat4;

impl<'a> Importer<'a> {
    pub(super) fn camera(
        &self,
        camera: &gltf::Camera,
        world: DMat4,
        node_name: &str,
    ) -> Result<Camera> {
        let element = format!("cameras[{}]", camera.index());
        let (projection, znear, zfar) = match camera.projection() {
            gltf::camera::Projection::Perspective(p) => {
                let yfov = p.yfov();
                if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
                    return Err(self.err(&element, format!("yfov {yfov} must be in (0, π)")));
                }
                if let Some(a) = p.aspect_ratio().filter(|a| !(a.is_finite() && *a > 0.0)) {
                    return Err(self.err(&element, format!("aspectRatio {a} must be positive")));
                }
                if !(p.znear() > 0.0 && p.znear().is_finite()) {
                    return Err(self.err(&element, format!("znear {} must be positive", p.znear())));
                }
                if let Some(f) = p.zfar().filter(|f| !(*f > p.znear())) {
                    return Err(self.err(
                        &element,
                        format!("zfar {f} must be greater than znear {}", p.znear()),
                    ));
                }
                let aspect = p.aspect_ratio();
                (
                    Projection::Perspective { yfov, aspect },
                    p.znear(),
                    p.zfar(),
                )
            }
            gltf::camera::Projection::Orthographic(o) => {
                let (xmag, ymag) = (o.xmag().abs(), o.ymag().abs());
                if !(xmag > 0.0 && ymag > 0.0 && xmag.is_finite() && ymag.is_finite()) {
                    return Err(self.err(&element, "xmag and ymag must be non-zero and finite"));
                }
                if !(o.znear() >= 0.0 && o.zfar() > o.znear()) {
                    return Err(self.err(
                        &element,
                        format!(
                            "znear {} must not be negative and zfar {} must be greater",
                            o.znear(),
                            o.zfar()
                        ),
                    ));
                }
                (
                    Projection::Orthographic { xmag, ymag },
                    o.znear(),
                    Some(o.zfar()),
                )
            }
        };
        let name = camera
            .name()
            .map_or_else(|| node_name.to_string(), str::to_string);
        Ok(Camera {
            name,
            projection,
            transform: world,
            aperture_radius: 0.0,
            focus_distance: 1.0,
            clip_near: znear.max(0.0) as f64,
            clip_far: zfar.filter(|f| f.is_finite() && *f > znear).map(f64::from),
            fit: Default::default(),
            motion: Vec::new(),
        })
    }
}
