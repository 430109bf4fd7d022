//! Ingest: scene files to the internal [`Scene`]. glTF is read natively; the embedded
//! default scene is the Cornell box of `scenes/cornell-box`.

pub mod animation;
pub mod gltf;

pub mod image;
pub mod skinning;
pub mod tangents;
pub mod uri;
pub mod usd;
pub mod vdb;
pub mod vol;

use crate::error::{Error, Result};
use crate::scene::{self, Scene, Texture, Wrap};
use glam::{DMat4, Vec3};
use std::path::Path;
use std::sync::Arc;

/// Name the embedded default scene goes by in messages and metadata.
pub const DEFAULT_SCENE: &str = "<default: cornell-box>";

const CORNELL_BOX: &[u8] = include_bytes!("../../scenes/cornell-box/cornell-box.gltf");

/// The embedded default scene: the Cornell box.
pub fn default_scene() -> Result<Scene> {
    gltf::import(CORNELL_BOX, DEFAULT_SCENE, None)
}

/// Frames per second when none is given: a glTF frame F is the time F / fps.
pub const DEFAULT_FPS: f64 = 24.0;

/// How to read a scene: options that only some formats use.
#[derive(Clone, Debug)]
pub struct LoadOptions {
    /// The frame of an animation: a USD stage's time code (default: its start time code);
    /// in glTF, the time frame / `fps` seconds (default: the nodes' rest transforms).
    pub frame: Option<f64>,
    /// Frames per second of glTF animations.
    pub fps: f64,
    /// The shutter's opening and closing in frames relative to the frame, where the
    /// stage does not say (or to override it); an open shutter blurs what moves.
    pub shutter: Option<(f64, f64)>,
    /// Blur over the open shutter (else the frame's instant is rendered and the motion
    /// over the shutter serves the motion and velocity layers alone).
    pub motion_blur: bool,
    /// The motion or velocity layer is asked for: where the shutter is closed, what moves
    /// gets its motion over [`VECTOR_INTERVAL`] anyway, without blur.
    pub vectors: bool,
    /// Run usd-core's validators (USD stages); their findings are warnings...
    pub validate: bool,
    /// ...unless strict: then an error refuses the stage.
    pub strict: bool,
    /// USD variant selections, `SET=NAME` or `/PRIM:SET=NAME`.
    pub variants: Vec<String>,
    /// USD purposes rendered besides default (comma-separated).
    pub purpose: String,
    /// Load USD payloads.
    pub payloads: bool,
    /// The USD RenderSettings prim to render by (default: the stage's
    /// `renderSettingsPrimPath`, else its first RenderSettings prim).
    pub render_settings: Option<String>,
    /// The glTF KHR_materials_variants variant to render (by name).
    pub material_variant: Option<String>,
    /// The glTF animation that plays (by name or index; default: the file's animations).
    pub animation: Option<String>,
    /// How long the USD plugin may take to convert a stage before it is stopped.
    pub plugin_timeout: std::time::Duration,
}

/// The interval (frames around the frame) over which motion is taken for the motion and
/// velocity layers where the shutter is closed: Cycles' vector pass likewise looks half a
/// frame each way.
pub const VECTOR_INTERVAL: (f64, f64) = (-0.5, 0.5);

/// Default of [`LoadOptions::plugin_timeout`]: generous for the largest stages, finite for
/// a plugin that hangs.
pub const DEFAULT_PLUGIN_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(1800);

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            frame: None,
            fps: DEFAULT_FPS,
            shutter: None,
            motion_blur: true,
            vectors: false,
            validate: true,
            strict: false,
            variants: Vec::new(),
            purpose: "render".into(),
            payloads: true,
            render_settings: None,
            material_variant: None,
            animation: None,
            plugin_timeout: DEFAULT_PLUGIN_TIMEOUT,
        }
    }
}

/// Loads a scene file, choosing the importer by extension.
pub fn load(path: &Path, options: &LoadOptions) -> Result<Scene> {
    let mut scene = load_format(path, options)?;
    set_shutter(&mut scene, options);
    Ok(scene)
}

/// The shutter of `options` (where it is open) as the scene's, and its blur; for the
/// motion layers, [`VECTOR_INTERVAL`] without blur where there is none.
fn set_shutter(scene: &mut Scene, options: &LoadOptions) {
    if let Some((open, close)) = options.shutter.filter(|(open, close)| close > open) {
        scene.shutter = Some(scene::Shutter {
            open,
            close,
            blur: true,
        });
    }
    if let Some(shutter) = &mut scene.shutter {
        shutter.blur &= options.motion_blur;
    } else if vectors_around_the_frame(options) {
        let (open, close) = VECTOR_INTERVAL;
        scene.shutter = Some(scene::Shutter {
            open,
            close,
            blur: false,
        });
    }
}

/// The shutter the glTF importer samples motion over, frames relative to the frame: the
/// open one asked for, else [`VECTOR_INTERVAL`] for the motion layers.
fn motion_interval(options: &LoadOptions) -> Option<(f64, f64)> {
    options
        .shutter
        .filter(|(open, close)| close > open)
        .or(vectors_around_the_frame(options).then_some(VECTOR_INTERVAL))
}

/// Whether the motion layers take their motion over [`VECTOR_INTERVAL`]: they are asked
/// for and a frame is given. Without a frame a glTF file shows its rest transforms, which
/// lie at no time of its animations (and asking for a layer must not change the image).
fn vectors_around_the_frame(options: &LoadOptions) -> bool {
    options.vectors && options.frame.is_some()
}

/// [`load`] by the file's format.
fn load_format(path: &Path, options: &LoadOptions) -> Result<Scene> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    match ext.as_str() {
        "gltf" | "glb" => gltf::load(
            path,
            // An open shutter opens around frame 0 where no frame is given.
            options
                .frame
                .or(motion_interval(options).map(|_| 0.0))
                .map(|f| f / options.fps),
            gltf::Choices {
                material_variant: options.material_variant.as_deref(),
                animation: options.animation.as_deref(),
                shutter: motion_interval(options).map(|(open, close)| {
                    let frame = options.frame.unwrap_or(0.0);
                    ((frame + open) / options.fps, (frame + close) / options.fps)
                }),
            },
        ),
        scene::file::EXTENSION => scene::file::read(path),
        e if usd::EXTENSIONS.contains(&e) => {
            let mut scene = usd::load(path, options)?;
            if options.animation.is_some() {
                scene.warnings.push(format!(
                    "{}: --animation chooses among a glTF file's animations; a USD stage plays its time samples at --frame",
                    path.display()
                ));
            }
            Ok(scene)
        }
        _ => Err(Error::bad_input(
            path,
            "file",
            "unknown scene format (expected .gltf, .glb, .usd, .usda, .usdc, .usdz or a \
             .lucerna scene file)",
        )),
    }
}

/// Reads a scene (the embedded Cornell box without a path) and logs its warnings.
pub fn load_scene(path: Option<&Path>, options: &LoadOptions) -> Result<Scene> {
    let scene = match path {
        Some(p) => load(p, options)?,
        None => {
            let mut scene = default_scene()?;
            set_shutter(&mut scene, options);
            scene
        }
    };
    for w in &scene.warnings {
        log::warn!("{w}");
    }
    Ok(scene)
}

/// Replaces the scene's environment with a constant radiance.
pub fn set_constant_environment(scene: &mut Scene, radiance: Vec3) {
    scene.environment = Some(scene::Environment::Constant(radiance));
}

/// Replaces the scene's environment with a lat-long map read from `path` (OpenEXR, Radiance
/// HDR, TIFF, PNG, JPEG or WebP; integer images are taken as sRGB-encoded, float ones as
/// linear) times `scale`.
pub fn set_environment_map(scene: &mut Scene, path: &Path, scale: Vec3) -> Result<()> {
    let decoded =
        image::read_file(path).map_err(|r| Error::bad_input(path, "environment map", r))?;
    // Decode to linear floats once: the environment is sampled as linear radiance, and
    // integer images are sRGB-encoded.
    let texels = match decoded.texels {
        f @ scene::Texels::RgbaF32(_) => f,
        integer => {
            let texture = Texture {
                name: String::new(),
                width: decoded.width,
                height: decoded.height,
                texels: Arc::new(integer),
                mips: Default::default(),
                wrap_u: Wrap::Repeat,
                wrap_v: Wrap::ClampToEdge,
                nearest: true,
                mipmaps: true,
                udim: None,
            };
            scene::Texels::RgbaF32(
                (0..decoded.height)
                    .flat_map(|y| (0..decoded.width).map(move |x| (x, y)))
                    .map(|(x, y)| texture.texel_linear(x, y, true).to_array())
                    .collect(),
            )
        }
    };
    scene.textures.push(Texture {
        name: path.display().to_string(),
        width: decoded.width,
        height: decoded.height,
        texels: Arc::new(texels),
        mips: Default::default(),
        wrap_u: Wrap::Repeat,
        wrap_v: Wrap::ClampToEdge,
        nearest: false,
        mipmaps: true,
        udim: None,
    });
    scene.environment = Some(scene::Environment::LatLong {
        texture: (scene.textures.len() - 1) as u32,
        scale,
        rotation: DMat4::IDENTITY,
    });
    Ok(())
}

/// How a checkpoint recognises its scene whatever path names it: the canonical path and a
/// fingerprint of the file's bytes (64-bit FNV-1a over 8-byte words, and the length), as
/// hex. `None` for the embedded scene or a file that cannot be read.
pub fn scene_identity(path: Option<&Path>) -> Option<(String, String)> {
    let path = path?;
    let canonical = std::fs::canonicalize(path).ok()?;
    let mut file = std::fs::File::open(&canonical).ok()?;
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    let mut length: u64 = 0;
    let mut buffer = vec![0u8; 1 << 20];
    loop {
        use std::io::Read;
        let n = match file.read(&mut buffer) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(_) => return None,
        };
        length += n as u64;
        for word in buffer[..n].chunks(8) {
            let mut bytes = [0u8; 8];
            bytes[..word.len()].copy_from_slice(word);
            hash = (hash ^ u64::from_le_bytes(bytes)).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    Some((
        canonical.to_string_lossy().into_owned(),
        format!("{hash:016x}-{length}"),
    ))
}
