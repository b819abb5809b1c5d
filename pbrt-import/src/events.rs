//! The streaming output: events a [`SceneSink`] receives while the parser runs.

use std::path::Path;
use std::sync::Arc;

use crate::error::SinkError;
use crate::lexer::Loc;
use crate::math::Mat4;
use crate::{ElementId, FileId, MaterialId, ObjectId};

/// How a file was reached.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Via {
    /// The file passed to [`crate::parse_file`].
    Entry,
    /// `Include` (textual; shares all state).
    Include,
    /// `Import` (pbrt-v4; graphics state is restored afterwards).
    Import,
}

/// A file starts or ends.
#[derive(Clone, Debug)]
pub struct FileEvent<'a> {
    /// Id used in every [`Loc`] from this file.
    pub file: FileId,
    /// Path as opened.
    pub path: &'a Path,
    /// 0 for the entry file, 1 for files it includes, ...
    pub depth: u32,
    /// How it was reached.
    pub via: Via,
    /// Included/imported directly from the entry file's world block: this file is an
    /// *element* (Moana: `isBeach/isBeach.pbrt` → `isBeach`).
    pub from_entry_world: bool,
    /// Element everything in this file belongs to (inherited by nested includes).
    pub element: Option<ElementId>,
    /// Element name (the path stem of the element's file).
    pub element_name: Option<&'a str>,
    /// Size of the file contents in bytes (decompressed for `.gz`).
    pub size_bytes: u64,
}

/// A resolved material: what a renderer needs for a base colour.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Id, unique per parse. `MaterialId(0)` is the default material.
    pub id: MaterialId,
    /// Name for `MakeNamedMaterial`, `None` for anonymous `Material` directives.
    pub name: Option<String>,
    /// pbrt material type (`matte`, `diffuse`, `coateddiffuse`, `interface`, ...).
    pub kind: String,
    /// Linear RGB base colour where known (constant, or a texture reduced to a constant).
    pub base_color: Option<[f32; 3]>,
    /// Name of the texture the base colour came from, if any.
    pub base_color_texture: Option<String>,
    /// `opacity` (v3 `uber`) where given.
    pub opacity: Option<[f32; 3]>,
    /// Image file the base colour comes from (an `imagemap` texture, possibly scaled: the
    /// image is multiplied by `base_color`), resolved against the scene file; `None` when the
    /// colour is constant or the file is missing.
    pub base_color_image: Option<std::path::PathBuf>,
    /// Ptex file the base colour comes from (a `ptex` texture, resolved against the scene file;
    /// Moana's base package: the mesh group's `<colorMap>/<group>.ptx`); its sample replaces
    /// the base colour, by face ([`Mesh::face_ids`]).
    pub ptex: Option<std::path::PathBuf>,
    /// Perceptual roughness in [0, 1] where the model has one (defaults per model applied).
    pub roughness: Option<f32>,
    /// Metalness in [0, 1] (1 for `metal`/`conductor`/`mirror`, `metallic` for `disney`).
    pub metallic: Option<f32>,
    /// Where it was defined.
    pub loc: Loc,
}

/// The current `AreaLightSource` attached to shapes.
#[derive(Clone, Debug, PartialEq)]
pub struct AreaLight {
    /// pbrt type (`diffuse`).
    pub kind: String,
    /// Emitted radiance `L` times `scale`, linear RGB, where known.
    pub radiance: Option<[f32; 3]>,
    /// `twosided`.
    pub two_sided: bool,
}

/// Triangle mesh geometry. Quads and polygons are already split into triangles.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions in shape space.
    pub positions: Vec<[f32; 3]>,
    /// Per-vertex normals.
    pub normals: Option<Vec<[f32; 3]>>,
    /// Per-vertex texture coordinates.
    pub uvs: Option<Vec<[f32; 2]>>,
    /// Triangle vertex indices, three per triangle.
    pub indices: Vec<u32>,
    /// Per triangle, the Ptex face it belongs to (pbrt `faceIndices`, per patch of a
    /// `bilinearmesh`), bit 31 set on the second triangle (v0 v2 v3) of a split quad; `None`:
    /// triangle t is face t.
    pub face_ids: Option<Vec<u32>>,
}

/// Bit 31 of a [`Mesh::face_ids`] entry: the second half of a quad.
pub const FACE_SECOND_HALF: u32 = 1 << 31;

impl Mesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }
}

/// `curve` shape, kept as curves (never silently dropped).
#[derive(Clone, Debug, PartialEq)]
pub struct Curve {
    /// `basis`: `bezier` or `bspline`.
    pub basis: String,
    /// `type`: `flat`, `ribbon` or `cylinder`.
    pub curve_type: String,
    /// `degree` (2 or 3).
    pub degree: u32,
    /// Control points `P`.
    pub control_points: Vec<[f32; 3]>,
    /// Width at the start (`width0` or `width`).
    pub width0: f32,
    /// Width at the end (`width1` or `width`).
    pub width1: f32,
    /// Ribbon normals `N`, if given.
    pub normals: Option<Vec<[f32; 3]>>,
}

/// Geometry of a shape.
#[derive(Clone, Debug, PartialEq)]
pub enum Geometry {
    /// Triangles (`trianglemesh`, `plymesh`, `bilinearmesh`, `loopsubdiv` cage, tessellated quadrics).
    Mesh(Mesh),
    /// A `curve` shape.
    Curve(Curve),
    /// A shape type this importer does not convert (`nurbs`, `heightfield`, `cone`, ...);
    /// counted in [`crate::ParseStats::unsupported_shapes`] and warned about.
    Unsupported,
}

/// One `Shape` directive with everything resolved.
#[derive(Clone, Debug)]
pub struct ShapeEvent {
    /// Document order of the `Shape` directive (0, 1, ...), also for out-of-order PLY shapes.
    pub seq: u64,
    /// pbrt shape type (`trianglemesh`, `plymesh`, `sphere`, `curve`, ...).
    pub kind: String,
    /// The CTM at the `Shape` directive: world-from-shape outside object definitions,
    /// object(instance)-from-shape inside `ObjectBegin`/`ObjectEnd` (`object` is `Some`).
    /// With `ActiveTransform`, the start-time transform.
    pub parent_from_shape: Mat4,
    /// `ReverseOrientation` was in effect.
    pub reverse_orientation: bool,
    /// Resolved material, including v3 shape-level overrides.
    pub material: Arc<Material>,
    /// `texture alpha` name.
    pub alpha_texture: Option<String>,
    /// Constant `float alpha`, when given (also a constant float texture's value).
    pub alpha: Option<f32>,
    /// Image file of the `texture alpha` (an `imagemap` float texture), resolved.
    pub alpha_image: Option<std::path::PathBuf>,
    /// Area light attached to the shape.
    pub area_light: Option<Arc<AreaLight>>,
    /// The object being defined, if the shape is inside `ObjectBegin`.
    pub object: Option<ObjectId>,
    /// The element the shape belongs to (see [`FileEvent::from_entry_world`]).
    pub element: Option<ElementId>,
    /// For `plymesh`: the file the geometry came from.
    pub source_path: Option<std::path::PathBuf>,
    /// Position of the `Shape` directive.
    pub loc: Loc,
    /// The geometry.
    pub geometry: Geometry,
}

/// `ObjectBegin` / `ObjectEnd`.
#[derive(Clone, Debug)]
pub struct ObjectEvent<'a> {
    /// The object (a redefinition under pbrt-v3 gets a fresh id).
    pub object: ObjectId,
    /// Its name.
    pub name: &'a str,
    /// Element the definition is in.
    pub element: Option<ElementId>,
    /// Position of the directive.
    pub loc: Loc,
}

/// `ObjectInstance`.
#[derive(Clone, Debug)]
pub struct InstanceEvent<'a> {
    /// The instanced object. Under pbrt-v4 it may be defined later in the file
    /// (forward reference); the parse fails at the end if it never is.
    pub object: ObjectId,
    /// Its name.
    pub name: &'a str,
    /// CTM at the directive: world-from-instance, or, for nested instancing
    /// (`ObjectInstance` inside `ObjectBegin`), parent-object-from-instance.
    pub parent_from_instance: Mat4,
    /// The object being defined when this instance is nested (extension).
    pub inside: Option<ObjectId>,
    /// Element.
    pub element: Option<ElementId>,
    /// Position.
    pub loc: Loc,
}

/// A `Camera` directive, reported at `WorldBegin` (or end of input) so the film is known.
#[derive(Clone, Debug)]
pub struct CameraEvent<'a> {
    /// pbrt camera type (`perspective`, `orthographic`, `realistic`, `spherical`).
    pub kind: String,
    /// The CTM at `Camera` (pbrt's camera space is left-handed, +z forward).
    pub camera_from_world: Mat4,
    /// Its inverse.
    pub world_from_camera: Mat4,
    /// Full field of view in degrees of the shorter image axis (perspective; default 90).
    pub fov_deg: Option<f32>,
    /// `screenwindow` `[xmin xmax ymin ymax]`.
    pub screen_window: Option<[f32; 4]>,
    /// `lensradius`.
    pub lens_radius: f32,
    /// `focaldistance`.
    pub focal_distance: Option<f32>,
    /// Film `xresolution`, `yresolution` (defaults 1280x720).
    pub resolution: [u32; 2],
    /// File with the `Camera` directive (the adapter names cameras by its stem).
    pub path: &'a Path,
    /// Position of the `Camera` directive.
    pub loc: Loc,
}

/// A `LightSource`.
#[derive(Clone, Debug)]
pub struct LightEvent {
    /// pbrt light type (`infinite`, `distant`, `point`, `spot`, ...).
    pub kind: String,
    /// CTM at the directive.
    pub world_from_light: Mat4,
    /// `L` or `I` times `scale`, linear RGB, where known.
    pub color: Option<[f32; 3]>,
    /// `from` (point/spot/distant), if given.
    pub from: Option<[f32; 3]>,
    /// `to` (spot/distant), if given.
    pub to: Option<[f32; 3]>,
    /// Environment map (`mapname` v3 / `filename` v4), if given.
    pub map: Option<String>,
    /// `map` resolved against the scene file.
    pub map_path: Option<std::path::PathBuf>,
    /// Spot: `coneangle` and `conedelta` in degrees (defaults 30 and 5).
    pub cone_deg: Option<[f32; 2]>,
    /// Inside `ObjectBegin` (pbrt ignores these; reported for completeness).
    pub object: Option<ObjectId>,
    /// Element.
    pub element: Option<ElementId>,
    /// Position.
    pub loc: Loc,
}

/// A non-fatal problem.
#[derive(Clone, Debug, PartialEq)]
pub struct Warning {
    /// Where, when there is a place.
    pub loc: Option<Loc>,
    /// What.
    pub message: String,
}

/// Receives the scene as it is parsed. All methods default to doing nothing.
///
/// Calls come from the parsing thread, in document order, except that with
/// [`crate::PlyLoading::Parallel`] `plymesh` shapes arrive later, in batches (each
/// [`ShapeEvent`] still carries its own transform, material, object, element and `seq`).
/// Every shape has been delivered before [`crate::parse_file`] returns.
pub trait SceneSink {
    /// A file starts.
    fn file_enter(&mut self, _e: &FileEvent<'_>) -> Result<(), SinkError> {
        Ok(())
    }
    /// A file ends.
    fn file_exit(&mut self, _e: &FileEvent<'_>) -> Result<(), SinkError> {
        Ok(())
    }
    /// A material was defined (named, anonymous, or a v3 shape-level override).
    fn material(&mut self, _m: &Arc<Material>) -> Result<(), SinkError> {
        Ok(())
    }
    /// A shape with its geometry.
    fn shape(&mut self, _s: ShapeEvent) -> Result<(), SinkError> {
        Ok(())
    }
    /// `ObjectBegin`.
    fn object_begin(&mut self, _e: &ObjectEvent<'_>) -> Result<(), SinkError> {
        Ok(())
    }
    /// `ObjectEnd`.
    fn object_end(&mut self, _e: &ObjectEvent<'_>) -> Result<(), SinkError> {
        Ok(())
    }
    /// `ObjectInstance`.
    fn object_instance(&mut self, _e: &InstanceEvent<'_>) -> Result<(), SinkError> {
        Ok(())
    }
    /// A camera.
    fn camera(&mut self, _e: &CameraEvent<'_>) -> Result<(), SinkError> {
        Ok(())
    }
    /// A light source.
    fn light(&mut self, _e: &LightEvent) -> Result<(), SinkError> {
        Ok(())
    }
    /// A warning (also logged through `tracing`).
    fn warning(&mut self, _w: &Warning) {}
}

/// A sink that keeps everything (tests, small scenes). Do not use it for Moana.
#[derive(Debug, Default)]
pub struct CollectSink {
    /// Shapes in arrival order.
    pub shapes: Vec<ShapeEvent>,
    /// Materials in definition order.
    pub materials: Vec<Arc<Material>>,
    /// `(object, name)` for each `ObjectBegin`.
    pub objects: Vec<(ObjectId, String)>,
    /// `(object, name, parent_from_instance, inside)` per `ObjectInstance`.
    pub instances: Vec<(ObjectId, String, Mat4, Option<ObjectId>)>,
    /// Cameras with their file stem.
    pub cameras: Vec<(String, CameraEvent<'static>)>,
    /// Lights.
    pub lights: Vec<LightEvent>,
    /// `(path, depth, via, element name)` per file entered.
    pub files: Vec<(std::path::PathBuf, u32, Via, Option<String>)>,
    /// Warnings.
    pub warnings: Vec<Warning>,
}

impl SceneSink for CollectSink {
    fn file_enter(&mut self, e: &FileEvent<'_>) -> Result<(), SinkError> {
        self.files.push((
            e.path.to_path_buf(),
            e.depth,
            e.via,
            e.element_name.map(str::to_owned),
        ));
        Ok(())
    }
    fn material(&mut self, m: &Arc<Material>) -> Result<(), SinkError> {
        self.materials.push(m.clone());
        Ok(())
    }
    fn shape(&mut self, s: ShapeEvent) -> Result<(), SinkError> {
        self.shapes.push(s);
        Ok(())
    }
    fn object_begin(&mut self, e: &ObjectEvent<'_>) -> Result<(), SinkError> {
        self.objects.push((e.object, e.name.to_owned()));
        Ok(())
    }
    fn object_instance(&mut self, e: &InstanceEvent<'_>) -> Result<(), SinkError> {
        self.instances.push((
            e.object,
            e.name.to_owned(),
            e.parent_from_instance,
            e.inside,
        ));
        Ok(())
    }
    fn camera(&mut self, e: &CameraEvent<'_>) -> Result<(), SinkError> {
        let stem = e
            .path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let owned = CameraEvent {
            path: Path::new(""),
            kind: e.kind.clone(),
            ..*e
        };
        self.cameras.push((stem, owned));
        Ok(())
    }
    fn light(&mut self, e: &LightEvent) -> Result<(), SinkError> {
        self.lights.push(e.clone());
        Ok(())
    }
    fn warning(&mut self, w: &Warning) {
        self.warnings.push(w.clone());
    }
}
