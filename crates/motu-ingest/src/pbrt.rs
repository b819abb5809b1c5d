//! pbrt events → scene model.

use crate::{IngestError, IngestOptions, IngestReport};
use glam::{Mat3, Mat4, Vec3};
use motu_scene::{
    Camera, ElementId, GeometryStore, Light, LightKind, Material, MaterialId, MeshData,
    PrototypeId, Scene, SceneBuilder, SceneError, Texture, Transform34,
};
use pbrt_import::{
    CameraEvent, FileEvent, Geometry, InstanceEvent, LightEvent, ObjectEvent, ParseOptions,
    PlyLoading, SceneSink, ShapeEvent, SinkError, VersionOption, Warning,
};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Warnings kept verbatim in the report (all are counted and logged).
const KEPT_WARNINGS: usize = 200;

struct Adapter {
    b: SceneBuilder,
    objects: HashMap<pbrt_import::ObjectId, PrototypeId>,
    materials: HashMap<pbrt_import::MaterialId, MaterialId>,
    /// Materials derived per shape: (material, alpha image, alpha bits, emission bits).
    derived: HashMap<DerivedKey, MaterialId>,
    elements: HashMap<pbrt_import::ElementId, ElementId>,
    files: HashMap<pbrt_import::FileId, PathBuf>,
    camera_names: HashMap<String, u32>,
    cameras: Vec<Camera>,
    report: IngestReport,
    curve_ribbons: bool,
    /// Curve ribbons gathered per (prototype, material, element), flushed as meshes.
    curve_meshes: HashMap<(PrototypeId, MaterialId, ElementId), MeshData>,
    progress: Option<crate::ProgressFn>,
    bytes_entered: u64,
}

/// Shapes that stand for smooth surfaces: tessellated quadrics and subdivision surfaces get
/// smoothed vertex normals when they carry none (a triangle mesh without `N` stays faceted,
/// as pbrt renders it).
fn asks_for_smooth_normals(kind: &str) -> bool {
    matches!(
        kind,
        "loopsubdiv" | "sphere" | "cylinder" | "disk" | "cone" | "paraboloid" | "hyperboloid"
    )
}

/// Area-weighted averages of the faces around each vertex (zero-area vertices get +z).
fn smooth_normals(positions: &[[f32; 3]], indices: &[u32]) -> Vec<[f32; 3]> {
    let mut acc = vec![Vec3::ZERO; positions.len()];
    for t in indices.chunks_exact(3) {
        let (Some(a), Some(b), Some(c)) = (
            positions.get(t[0] as usize),
            positions.get(t[1] as usize),
            positions.get(t[2] as usize),
        ) else {
            continue;
        };
        let (a, b, c) = (
            Vec3::from_array(*a),
            Vec3::from_array(*b),
            Vec3::from_array(*c),
        );
        let n = (b - a).cross(c - a);
        for &i in t {
            acc[i as usize] += n;
        }
    }
    acc.into_iter()
        .map(|n| n.try_normalize().unwrap_or(Vec3::Z).to_array())
        .collect()
}

type DerivedKey = (MaterialId, Option<PathBuf>, u32, [u32; 3]);

/// Ribbon triangles gathered into one mesh before it is stored.
const CURVE_MESH_TRIANGLES: usize = 1 << 20;

fn mat4(m: &pbrt_import::Mat4) -> Mat4 {
    Mat4::from_cols_array(&m.to_cols_array())
}

fn is_affine(m: &Mat4) -> bool {
    let r = m.row(3);
    r.x == 0.0 && r.y == 0.0 && r.z == 0.0 && r.w == 1.0
}

fn sink_err(e: SceneError) -> SinkError {
    SinkError::new(e)
}

impl Adapter {
    fn warn(&mut self, msg: String) {
        tracing::warn!("{msg}");
        if self.report.warnings.len() < KEPT_WARNINGS {
            self.report.warnings.push(msg);
        }
    }

    fn where_(&self, loc: &pbrt_import::Loc) -> String {
        let path = self
            .files
            .get(&loc.file)
            .map(|p| p.display().to_string())
            .unwrap_or_default();
        format!("{path}:{}:{}", loc.line, loc.column)
    }

    fn element(&self, e: Option<pbrt_import::ElementId>) -> ElementId {
        e.and_then(|e| self.elements.get(&e).copied())
            .unwrap_or(Scene::MAIN_ELEMENT)
    }

    fn prototype(
        &mut self,
        object: pbrt_import::ObjectId,
        name: &str,
        element: Option<pbrt_import::ElementId>,
    ) -> Result<PrototypeId, SinkError> {
        if let Some(&p) = self.objects.get(&object) {
            return Ok(p);
        }
        let e = self.element(element);
        let p = self.b.add_prototype(name, e).map_err(sink_err)?;
        self.objects.insert(object, p);
        Ok(p)
    }

    fn material(&mut self, m: &Arc<pbrt_import::Material>) -> Result<MaterialId, SinkError> {
        if let Some(&id) = self.materials.get(&m.id) {
            return Ok(id);
        }
        let opacity = m.opacity.map(|o| (o[0] + o[1] + o[2]) / 3.0).unwrap_or(1.0);
        // A Ptex file replaces the colour (and an image, which pbrt would not combine with it).
        let base_color_texture = match (&m.ptex, &m.base_color_image) {
            (Some(path), _) => Some(self.b.add_texture(Texture {
                path: path.clone(),
                is_alpha: false,
                ptex: true,
            })),
            (None, Some(path)) => Some(self.b.add_texture(Texture {
                path: path.clone(),
                is_alpha: false,
                ptex: false,
            })),
            (None, None) => None,
        };
        let id = self
            .b
            .add_material(Material {
                name: m
                    .name
                    .clone()
                    .unwrap_or_else(|| format!("{}#{}", m.kind, m.id.0)),
                base_color: m.base_color.unwrap_or([0.5; 3]),
                opacity,
                alpha_texture: None,
                base_color_texture,
                roughness: m.roughness.unwrap_or(0.5),
                metallic: m.metallic.unwrap_or(0.0),
                emission: [0.0; 3],
                ptex: m.ptex.clone(),
            })
            .map_err(sink_err)?;
        self.materials.insert(m.id, id);
        Ok(id)
    }

    /// The shape's material with its own coverage (`alpha`) and emission (area light), which
    /// pbrt attaches to shapes and motu to materials: one derived material per combination.
    fn shape_material(
        &mut self,
        base: MaterialId,
        alpha_image: Option<&PathBuf>,
        alpha: Option<f32>,
        emission: Option<[f32; 3]>,
    ) -> Result<MaterialId, SinkError> {
        let alpha = alpha.filter(|a| *a < 1.0);
        if alpha_image.is_none() && alpha.is_none() && emission.is_none() {
            return Ok(base);
        }
        let e = emission.unwrap_or([0.0; 3]);
        let key: DerivedKey = (
            base,
            alpha_image.cloned(),
            alpha.unwrap_or(1.0).to_bits(),
            e.map(f32::to_bits),
        );
        if let Some(&id) = self.derived.get(&key) {
            return Ok(id);
        }
        let mut m = self.b.material(base).clone();
        if let Some(path) = alpha_image {
            m.alpha_texture = Some(self.b.add_texture(Texture {
                path: path.clone(),
                is_alpha: true,
                ptex: false,
            }));
        }
        if let Some(a) = alpha {
            m.opacity = m.opacity.min(a);
        }
        m.emission = e;
        let id = self.b.add_material(m).map_err(sink_err)?;
        self.derived.insert(key, id);
        Ok(id)
    }
}

impl Adapter {
    /// Stores gathered curve ribbons: one group, or all of them (`None`).
    fn flush_curves(
        &mut self,
        only: Option<(PrototypeId, MaterialId, ElementId)>,
    ) -> Result<(), SinkError> {
        let keys: Vec<_> = match only {
            Some(k) => vec![k],
            None => {
                let mut k: Vec<_> = self.curve_meshes.keys().copied().collect();
                k.sort_unstable(); // deterministic mesh ids
                k
            }
        };
        for key in keys {
            let Some(data) = self.curve_meshes.remove(&key) else {
                continue;
            };
            if data.indices.is_empty() {
                continue;
            }
            let (proto, material, element) = key;
            self.b
                .add_mesh_owned(proto, "curves", material, element, data)
                .map_err(sink_err)?;
            self.report.meshes += 1;
        }
        Ok(())
    }
}

impl SceneSink for Adapter {
    fn file_enter(&mut self, e: &FileEvent<'_>) -> Result<(), SinkError> {
        self.files.insert(e.file, e.path.to_path_buf());
        self.report.files += 1;
        self.bytes_entered += e.size_bytes;
        if let Some(p) = &self.progress {
            (p.0)(self.bytes_entered, self.report.files);
        }
        if let (Some(id), Some(name)) = (e.element, e.element_name) {
            if !self.elements.contains_key(&id) {
                let el = self.b.element(name).map_err(sink_err)?;
                self.elements.insert(id, el);
            }
        }
        Ok(())
    }

    fn shape(&mut self, s: ShapeEvent) -> Result<(), SinkError> {
        self.report.shapes += 1;
        if let Some(p) = &s.source_path {
            self.report.input_files.push(p.clone());
        }
        let is_curve = matches!(s.geometry, Geometry::Curve(_));
        let mesh = match s.geometry {
            Geometry::Mesh(m) => m,
            Geometry::Curve(c) => {
                self.report.curves += 1;
                if !self.curve_ribbons {
                    return Ok(());
                }
                match crate::curves::ribbon(&c) {
                    Some(m) => {
                        self.report.curve_ribbons += 1;
                        self.report.curve_ribbon_triangles += (m.indices.len() / 3) as u64;
                        pbrt_import::Mesh {
                            positions: m.positions,
                            normals: None,
                            uvs: None,
                            indices: m.indices,
                            face_ids: None,
                        }
                    }
                    None => return Ok(()),
                }
            }
            Geometry::Unsupported => {
                self.report.unsupported_shapes += 1;
                return Ok(());
            }
        };
        let at = self.where_(&s.loc);
        let m = mat4(&s.parent_from_shape);
        if !is_affine(&m) || !m.is_finite() {
            self.report.skipped_shapes += 1;
            self.warn(format!(
                "{at}: shape '{}' has a projective or non-finite transform; skipped",
                s.kind
            ));
            return Ok(());
        }
        if mesh.indices.is_empty() {
            self.report.degenerate_meshes += 1;
            return Ok(());
        }
        let normal_m = Mat3::from_mat4(m).inverse().transpose();
        let mut mesh = mesh;
        // Smooth normals from the shape's own positions, before they are transformed.
        if mesh.normals.is_none() && asks_for_smooth_normals(&s.kind) {
            mesh.normals = Some(smooth_normals(&mesh.positions, &mesh.indices));
        }
        // Transformed in place: the parser's arrays become the mesh's (a copy was fresh pages
        // for every vertex of a Moana-scale parse: issue 48 item 1).
        let mut positions = mesh.positions;
        for p in &mut positions {
            *p = m.transform_point3(Vec3::from_array(*p)).to_array();
        }
        let normals = mesh.normals.map(|mut ns| {
            for n in &mut ns {
                *n = (normal_m * Vec3::from_array(*n))
                    .normalize_or_zero()
                    .to_array();
            }
            ns
        });
        let face_ids = mesh.face_ids.take();
        let data = MeshData {
            positions,
            normals,
            uvs: mesh.uvs,
            indices: mesh.indices,
        };
        let emission = s
            .area_light
            .as_ref()
            .map(|l| l.radiance.unwrap_or([1.0; 3]));
        if let (Some(l), None) = (emission, s.object) {
            // An emitter outside any object also lights the scene: a point light at its centre
            // with its power (L × area, two-sided emitters twice).
            let mut area = 0.0f32;
            let mut centre = Vec3::ZERO;
            for t in data.indices.chunks_exact(3) {
                let [a, b, c] = [0, 1, 2].map(|k| Vec3::from_array(data.positions[t[k] as usize]));
                let ta = 0.5 * (b - a).cross(c - a).length();
                area += ta;
                centre += ta * (a + b + c) / 3.0;
            }
            let two_sided = s.area_light.as_ref().is_some_and(|l| l.two_sided);
            let power = area * if two_sided { 2.0 } else { 1.0 };
            let peak = l.iter().cloned().fold(0.0f32, f32::max);
            if area > 0.0 && peak > 0.0 {
                let centre = centre / area;
                let radius = data
                    .positions
                    .iter()
                    .map(|p| Vec3::from_array(*p).distance(centre))
                    .fold(0.0f32, f32::max);
                self.b.add_light(Light {
                    kind: LightKind::Area,
                    color: l.map(|c| c / peak),
                    intensity: peak * power,
                    world_direction: [0.0; 3],
                    world_position: centre.to_array(),
                    cone_deg: None,
                    radius,
                    map: None,
                });
            }
        }
        let base_material = self.material(&s.material)?;
        let material =
            self.shape_material(base_material, s.alpha_image.as_ref(), s.alpha, emission)?;
        let element = self.element(s.element);
        let proto = match s.object {
            Some(o) => self.prototype(o, "object", s.element)?,
            None => Scene::ROOT,
        };
        if is_curve {
            // Ribbons of one prototype, material and element share meshes: one mesh per curve
            // would cost a mesh record and a BLAS geometry per ten triangles.
            let acc = self
                .curve_meshes
                .entry((proto, material, element))
                .or_default();
            let base = acc.positions.len() as u32;
            acc.positions.extend_from_slice(&data.positions);
            acc.indices.extend(data.indices.iter().map(|i| i + base));
            if acc.triangle_count() >= CURVE_MESH_TRIANGLES {
                self.flush_curves(Some((proto, material, element)))?;
            }
            return Ok(());
        }
        let name = match &s.source_path {
            Some(p) => p
                .file_stem()
                .map(|x| x.to_string_lossy().into_owned())
                .unwrap_or_default(),
            None => format!("{}@{}", s.kind, at),
        };
        let triangle_count = data.triangle_count();
        match self.b.add_mesh_owned(proto, &name, material, element, data) {
            Ok(id) => {
                self.report.meshes += 1;
                // Face ids matter only where a Ptex texture is sampled.
                let ptex = self.b.material(material).ptex.is_some();
                if let (true, Some(ids)) = (ptex, face_ids) {
                    if ids.len() == triangle_count {
                        if let Some(f) = motu_scene::PtexFaces::from_ids(&ids) {
                            self.b.set_ptex_faces(id, f);
                        }
                    }
                }
            }
            Err(SceneError::BadMesh { reason, .. }) => {
                self.report.skipped_shapes += 1;
                self.warn(format!("{at}: shape '{}' skipped: {reason}", s.kind));
            }
            Err(source) => return Err(SinkError::new(IngestError::Scene { at, source })),
        }
        Ok(())
    }

    fn object_begin(&mut self, e: &ObjectEvent<'_>) -> Result<(), SinkError> {
        self.prototype(e.object, e.name, e.element).map(|_| ())
    }

    fn object_instance(&mut self, e: &InstanceEvent<'_>) -> Result<(), SinkError> {
        let child = self.prototype(e.object, e.name, e.element)?;
        let parent = match e.inside {
            Some(o) => self.prototype(o, "object", e.element)?,
            None => Scene::ROOT,
        };
        let m = mat4(&e.parent_from_instance);
        if !is_affine(&m) || !m.is_finite() {
            let at = self.where_(&e.loc);
            self.warn(format!(
                "{at}: instance of '{}' has a projective or non-finite transform; skipped",
                e.name
            ));
            return Ok(());
        }
        let element = self.element(e.element);
        self.b
            .add_instance(parent, child, Transform34::from_mat4(m), element)
            .map_err(|source| {
                SinkError::new(IngestError::Scene {
                    at: self.where_(&e.loc),
                    source,
                })
            })
    }

    fn camera(&mut self, e: &CameraEvent<'_>) -> Result<(), SinkError> {
        let w = mat4(&e.world_from_camera);
        let eye = w.transform_point3(Vec3::ZERO);
        let forward = w.transform_vector3(Vec3::Z).normalize_or(Vec3::Z);
        let up = w.transform_vector3(Vec3::Y).normalize_or(Vec3::Y);
        let x = w.transform_vector3(Vec3::X);
        let mirror_x = x.dot(up.cross(forward)) < 0.0;
        let stem = e
            .path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "camera".into());
        let n = self.camera_names.entry(stem.clone()).or_insert(0);
        *n += 1;
        let name = if *n == 1 { stem } else { format!("{stem}_{n}") };
        if e.kind != "perspective" {
            let at = self.where_(&e.loc);
            self.warn(format!(
                "{at}: camera '{}' is rendered as perspective",
                e.kind
            ));
        }
        let mut cam = Camera::look_at(
            &name,
            eye,
            eye + forward,
            up,
            e.fov_deg.unwrap_or(90.0),
            e.resolution[0],
            e.resolution[1],
        );
        cam.mirror_x = mirror_x;
        self.cameras.push(cam);
        Ok(())
    }

    fn light(&mut self, e: &LightEvent) -> Result<(), SinkError> {
        let w = mat4(&e.world_from_light);
        let kind = match e.kind.as_str() {
            "distant" => LightKind::Distant,
            "point" => LightKind::Point,
            "spot" => LightKind::Spot,
            "infinite" => LightKind::Infinite,
            _ => LightKind::Other,
        };
        let from = Vec3::from_array(e.from.unwrap_or([0.0; 3]));
        let to = Vec3::from_array(e.to.unwrap_or([0.0, 0.0, 1.0]));
        let dir = w.transform_vector3(to - from).normalize_or_zero();
        let mut color = e.color.unwrap_or([1.0; 3]);
        let mut map = None;
        if let (LightKind::Infinite, Some(path)) = (kind, &e.map_path) {
            // An environment map lights as itself (importance-sampled by the renderers); its
            // mean times `L` × `scale` is the constant stand-in.
            match motu_texture::load_environment(path) {
                Ok((width, height, texels)) => {
                    let radiance: Vec<[f32; 3]> = texels
                        .iter()
                        .map(|t| {
                            std::array::from_fn(|i| {
                                let v = t[i] * color[i];
                                if v.is_finite() {
                                    v.max(0.0)
                                } else {
                                    0.0
                                }
                            })
                        })
                        .collect();
                    let n = radiance.len().max(1) as f64;
                    let mut sum = [0.0f64; 3];
                    for t in &radiance {
                        for i in 0..3 {
                            sum[i] += t[i] as f64;
                        }
                    }
                    color = sum.map(|s| (s / n) as f32);
                    let r = |i: usize| [w.x_axis[i], w.y_axis[i], w.z_axis[i]];
                    map = Some(motu_scene::EnvironmentMap {
                        width,
                        height,
                        radiance,
                        world_from_light: [r(0), r(1), r(2)],
                    });
                }
                Err(err) => {
                    let at = self.where_(&e.loc);
                    self.warn(format!(
                        "{at}: environment map not read ({err}); its constant colour is used"
                    ));
                }
            }
        }
        let intensity = color.iter().cloned().fold(0.0f32, f32::max);
        let color = if intensity > 0.0 {
            color.map(|c| c / intensity)
        } else {
            color
        };
        self.b.add_light(Light {
            kind,
            color,
            intensity,
            world_direction: dir.to_array(),
            world_position: w.transform_point3(from).to_array(),
            cone_deg: e.cone_deg,
            radius: 0.0,
            map,
        });
        Ok(())
    }

    fn warning(&mut self, w: &Warning) {
        let msg = match &w.loc {
            Some(loc) => format!("{}: {}", self.where_(loc), w.message),
            None => w.message.clone(),
        };
        if self.report.warnings.len() < KEPT_WARNINGS {
            self.report.warnings.push(msg);
        }
    }
}

/// Imports a pbrt-v3/v4 scene.
///
/// A file included several times by one file becomes one prototype with an instance edge
/// per inclusion where that is exact (see `pbrt_import::ParseOptions::share_repeated_includes`).
pub fn ingest_pbrt(
    path: &Path,
    options: &IngestOptions,
    geometry: Box<dyn GeometryStore>,
) -> Result<(Scene, IngestReport), IngestError> {
    ingest_pbrt_with(path, options, geometry, true)
}

fn ingest_pbrt_with(
    path: &Path,
    options: &IngestOptions,
    geometry: Box<dyn GeometryStore>,
    share_repeated_includes: bool,
) -> Result<(Scene, IngestReport), IngestError> {
    let _span = tracing::info_span!("parse", path = %path.display()).entered();
    let parse_options = ParseOptions {
        version: match options.pbrt_version {
            Some(3) => VersionOption::V3,
            Some(4) => VersionOption::V4,
            _ => VersionOption::Auto,
        },
        allow_missing: options.allow_missing,
        ply_loading: if options.parallel {
            PlyLoading::Parallel {
                batch_bytes: 64 << 20,
            }
        } else {
            PlyLoading::Sequential
        },
        share_repeated_includes,
        parallel_includes: options.parallel,
        ..Default::default()
    };
    let mut a = Adapter::new(options, geometry);
    let stats = pbrt_import::parse_file(path, &parse_options, &mut a)?;
    a.finish(path, &stats)
}

/// Imports Moana's JSON+OBJ base package (an element JSON, a scene list or a folder): the
/// same events as a pbrt parse, so the same scene for the same content.
pub fn ingest_moana_json(
    path: &Path,
    options: &IngestOptions,
    geometry: Box<dyn GeometryStore>,
) -> Result<(Scene, IngestReport), IngestError> {
    let _span = tracing::info_span!("parse", path = %path.display()).entered();
    let parse_options = ParseOptions {
        allow_missing: options.allow_missing,
        ..Default::default()
    };
    let mut a = Adapter::new(options, geometry);
    let stats = pbrt_import::moana_json::parse_moana_json(path, &parse_options, &mut a)?;
    a.finish(path, &stats)
}

impl Adapter {
    fn new(options: &IngestOptions, geometry: Box<dyn GeometryStore>) -> Self {
        let mut b = SceneBuilder::new(geometry);
        if let Some(dir) = &options.edge_spill_dir {
            b.spill_edges_to(dir);
        }
        Adapter {
            b,
            objects: HashMap::new(),
            materials: HashMap::new(),
            derived: HashMap::new(),
            elements: HashMap::new(),
            files: HashMap::new(),
            camera_names: HashMap::new(),
            cameras: Vec::new(),
            report: IngestReport::default(),
            curve_ribbons: options.curve_ribbons,
            curve_meshes: HashMap::new(),
            progress: options.progress.clone(),
            bytes_entered: 0,
        }
    }

    /// After the parse: curve meshes, the report's counts and inputs, cameras, the scene.
    fn finish(
        self,
        path: &Path,
        stats: &pbrt_import::ParseStats,
    ) -> Result<(Scene, IngestReport), IngestError> {
        let mut a = self;
        a.flush_curves(None).map_err(|source| IngestError::Curves {
            at: path.display().to_string(),
            source,
        })?;
        let skipped_curves = a.report.curves - a.report.curve_ribbons;
        if skipped_curves > 0 {
            a.warn(format!(
            "{skipped_curves} curve shapes counted but not converted (import with --curves ribbons to tessellate them)"
        ));
        }
        a.report.input_files.extend(stats.files.iter().cloned());
        a.report.input_files.sort_unstable();
        a.report.input_files.dedup();
        a.report.text_bytes = stats.text_bytes;
        a.report.ply_bytes = stats.ply_bytes;
        for m in &stats.missing {
            a.warn(format!(
                "{}: missing file skipped: {}",
                m.referenced_at,
                m.path.display()
            ));
        }
        // pbrt renders with the last camera: list it first so it is the default.
        for cam in a.cameras.drain(..).rev() {
            a.b.add_camera(cam);
        }
        let at = path.display().to_string();
        let scene =
            a.b.finish()
                .map_err(|source| IngestError::Scene { at, source })?;
        Ok((scene, a.report))
    }
}

#[cfg(test)]
mod tests;
