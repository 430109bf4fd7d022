//! KHR_lights_punctual lights placed by their node, and the light group lucerna's extras
//! give them.

use super::Importer;
use crate::error::Result;
use crate::scene::{Light, LightKind};
use glam::{DMat4, DVec3, Vec3};

impl<'a> Importer<'a> {
    pub(super) fn light(
        &mut self,
        light: &gltf::khr_lights_punctual::Light,
        world: DMat4,
        node_name: &str,
    ) -> Result<()> {
        let element = format!("KHR_lights_punctual.lights[{}]", light.index());
        let radiant = Vec3::from_array(light.color()) * light.intensity();
        if !radiant.is_finite() || radiant.min_element() < 0.0 {
            self.warn(
                &element,
                "colour × intensity is negative or not finite; light skipped",
            );
            return Ok(());
        }
        let position = world.transform_point3(DVec3::ZERO);
        let direction = world.transform_vector3(-DVec3::Z).normalize_or_zero();
        if direction == DVec3::ZERO {
            self.warn(&element, "node transform is degenerate; light skipped");
            return Ok(());
        }
        let kind = match light.kind() {
            gltf::khr_lights_punctual::Kind::Point => LightKind::Point {
                position,
                intensity: radiant,
            },
            gltf::khr_lights_punctual::Kind::Directional => LightKind::Directional {
                direction,
                irradiance: radiant,
                angle: 0.0,
            },
            gltf::khr_lights_punctual::Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => {
                // The extension's rule: 0 <= inner < outer <= π/2 (glTF-Validator: an error).
                if !(inner_cone_angle >= 0.0
                    && inner_cone_angle < outer_cone_angle
                    && outer_cone_angle <= std::f32::consts::FRAC_PI_2)
                {
                    return Err(self.err(
                        &element,
                        format!(
                            "spot.innerConeAngle {inner_cone_angle} and outerConeAngle {outer_cone_angle} must satisfy 0 <= inner < outer <= π/2"
                        ),
                    ));
                }
                LightKind::Spot {
                    position,
                    direction,
                    intensity: radiant,
                    inner_cone: inner_cone_angle,
                    outer_cone: outer_cone_angle,
                }
            }
        };
        self.scene.lights.push(Light {
            name: light
                .name()
                .map_or_else(|| node_name.to_string(), str::to_string),
            kind,
        });
        Ok(())
    }

    /// The light group a node's `extras` put it in: `{"lucerna": {"light_group": "key"}}`
    /// (its emitting meshes and its light go to `lg_key`).
    pub(super) fn light_group(&self, node: &gltf::Node, element: &str) -> Result<Option<String>> {
        let Some(raw) = node.extras() else {
            return Ok(None);
        };
        let value: serde_json::Value = serde_json::from_str(raw.get())
            .map_err(|e| self.err(format!("{element}.extras"), e.to_string()))?;
        match value.get("lucerna").and_then(|l| l.get("light_group")) {
            None => Ok(None),
            Some(serde_json::Value::String(group))
                if !group.is_empty()
                    && group.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') =>
            {
                Ok(Some(group.to_ascii_lowercase()))
            }
            Some(other) => Err(self.err(
                format!("{element}.extras.lucerna.light_group"),
                format!("{other} is not a group name (letters, digits and _)"),
            )),
        }
    }
}
