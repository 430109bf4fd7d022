//! What both targets do with a scene that loaded: prepare it and render a few pixels. A
//! reader that accepts a scene must hand the renderer something it can render (or refuse
//! with an error), and no NaN or Inf may reach a pixel.

use lucerna::film::aov::Aov;
use lucerna::integrator::LightSelect;
use lucerna::render::{self, RenderOptions};
use lucerna::scene::Scene;
use lucerna::world::World;

/// Memory a fuzzed scene may need, as `render --max-memory` would allow it (libFuzzer's own
/// limit, 2 GiB, would report a larger one as a crash).
const MAX_MEMORY: u64 = 1 << 30;

/// Builds the world for `scene` at 4x4 and renders one sample per pixel, panicking (a
/// finding) if a pixel is not finite. Scenes the memory estimate refuses are skipped, as the
/// command line refuses them.
pub fn render_a_few_pixels(scene: Scene) {
    if lucerna::world::build::estimate_memory(&scene).total() > MAX_MEMORY {
        return;
    }
    let Ok(world) = World::build(scene, None, Some((4, 4)), LightSelect::Power) else {
        return;
    };
    let options = RenderOptions {
        spp: Some(1),
        ..Default::default()
    };
    let (film, _) = render::render(&world, &options);
    for plane in film.planes(Aov::Beauty) {
        assert!(plane.iter().all(|v| v.is_finite()), "a pixel is not finite");
    }
}
