//! Geometry: `archive` primitives (one object per OBJ, placements streamed from the archive JSON),
//! OBJ shapes and `curve` primitives.

use std::path::Path;
use std::sync::Arc;

use super::json::Reader;
use super::obj::{self, ObjMesh};
use super::{non_finite_position, Ctx, CurveSpec, Importer, Stop};
use crate::events::{Curve, Geometry, Material, ObjectEvent, ShapeEvent};
use crate::math::{self, M64};
use crate::source::{classify, FileKind};
use crate::{Error, Loc, Location, MaterialId, ObjectId};

impl Importer<'_> {
    pub(super) fn archive_object(
        &mut self,
        path: &Path,
        referenced_at: Option<&Location>,
        ctx: &Ctx<'_>,
    ) -> Result<Option<ObjectId>, Error> {
        if let Some(&o) = self.archives.get(path) {
            return Ok(o);
        }
        if classify(path) == FileKind::Missing && self.opts.allow_missing {
            self.open(path, referenced_at, Some((ctx.element, ctx.name)))?;
            self.archives.insert(path.to_path_buf(), None);
            return Ok(None);
        }
        let object = self.new_object();
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let loc = Loc::default();
        self.sink.object_begin(&ObjectEvent {
            object,
            name: &name,
            element: Some(ctx.element),
            loc,
        })?;
        self.obj_shapes(path, referenced_at, Some(object), &math::IDENTITY, ctx)?;
        self.sink.object_end(&ObjectEvent {
            object,
            name: &name,
            element: Some(ctx.element),
            loc,
        })?;
        self.archives.insert(path.to_path_buf(), Some(object));
        Ok(Some(object))
    }

    pub(super) fn obj_shapes(
        &mut self,
        path: &Path,
        referenced_at: Option<&Location>,
        object: Option<ObjectId>,
        parent_from_shape: &M64,
        ctx: &Ctx<'_>,
    ) -> Result<(), Error> {
        let Some(input) = self.open(path, referenced_at, Some((ctx.element, ctx.name)))? else {
            return Ok(());
        };
        let m = math::to_f32(parent_from_shape);
        let result = obj::read::<Stop>(input.bytes.bytes(), |om: ObjMesh| {
            let mut material = ctx
                .mats
                .by_name
                .get(&om.material)
                .cloned()
                .unwrap_or_else(|| self.default_material.clone());
            let dir = ctx.mats.ptex_dirs.get(&material.id);
            if let (Some(dir), false) = (dir, om.group.is_empty()) {
                let key = (material.id, om.group.clone());
                material = match self.per_group.get(&key) {
                    Some(m) => m.clone(),
                    None => {
                        let m = Arc::new(Material {
                            id: MaterialId(self.next_material),
                            ptex: Some(dir.join(format!("{}.ptx", om.group))),
                            ..(*material).clone()
                        });
                        self.next_material += 1;
                        self.sink.material(&m).map_err(|e| Stop::Done(e.into()))?;
                        self.per_group.insert(key, m.clone());
                        m
                    }
                };
            }
            self.stats.shapes += 1;
            self.stats.triangles += om.mesh.triangle_count() as u64;
            let seq = self.seq;
            self.seq += 1;
            self.sink
                .shape(ShapeEvent {
                    seq,
                    kind: "objmesh".into(),
                    parent_from_shape: m,
                    reverse_orientation: false,
                    material,
                    alpha_texture: None,
                    alpha: None,
                    alpha_image: None,
                    area_light: None,
                    object,
                    element: Some(ctx.element),
                    source_path: Some(input.path.clone()),
                    loc: Loc {
                        file: input.file,
                        line: om.line,
                        column: 1,
                    },
                    geometry: Geometry::Mesh(om.mesh),
                })
                .map_err(|e| Stop::Done(e.into()))
        });
        result.map_err(|s| input.stop(s))
    }

    pub(super) fn archive_placements(
        &mut self,
        path: &Path,
        referenced_at: &Location,
        base: &M64,
        inside: Option<ObjectId>,
        ctx: &Ctx<'_>,
    ) -> Result<(), Error> {
        let Some(input) = self.open(path, Some(referenced_at), Some((ctx.element, ctx.name)))?
        else {
            return Ok(());
        };
        let mut r = Reader::new(input.bytes.bytes());
        let result = r.object::<Stop>(
            "an archive file (OBJ path → instances)",
            |r, obj_path, key_at| {
                let obj_path = self.resolve(&obj_path, &input.path);
                let object = self.archive_object(&obj_path, Some(&input.location(key_at)), ctx)?;
                let name = obj_path
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default();
                r.object::<Stop>(
                    "an archive's instance map (name → matrix)",
                    |r, _instance, _| {
                        let at = r.offset();
                        let v = r.numbers::<16>("an instance matrix")?;
                        if let Some(i) = non_finite_position(&v) {
                            return Err(r
                                .error(
                                    at,
                                    format!(
                                        "instance matrix holds a non-finite value (NaN or \
                                     infinity) at position {i}"
                                    ),
                                )
                                .into());
                        }
                        let m = math::from_pbrt(&v);
                        if let Some(object) = object {
                            let parent_from_instance = math::mul(base, &m);
                            self.instance(
                                object,
                                &name,
                                &parent_from_instance,
                                inside,
                                ctx.element,
                                input.loc(at),
                            )?;
                        }
                        Ok(())
                    },
                )
            },
        );
        result
            .and_then(|()| r.finish().map_err(Stop::Json))
            .map_err(|s| input.stop(s))
    }

    pub(super) fn curves(
        &mut self,
        path: &Path,
        referenced_at: &Location,
        base: &M64,
        inside: Option<ObjectId>,
        ctx: &Ctx<'_>,
        spec: &CurveSpec,
    ) -> Result<(), Error> {
        let Some(input) = self.open(path, Some(referenced_at), Some((ctx.element, ctx.name)))?
        else {
            return Ok(());
        };
        let m = math::to_f32(base);
        let mut r = Reader::new(input.bytes.bytes());
        let mut points: Vec<[f32; 3]> = Vec::new();
        let result = r.array::<Stop>("a curve file (a list of curves)", |r, _| {
            let at = r.offset();
            points.clear();
            r.array::<Stop>("a curve (a list of points)", |r, _| {
                let p_at = r.offset();
                let p = r.numbers::<3>("a curve point")?;
                if p.iter().any(|x| !x.is_finite()) {
                    return Err(r
                        .error(p_at, "curve point is not finite (NaN or infinity)")
                        .into());
                }
                points.push(p.map(|x| x as f32));
                Ok(())
            })?;
            if points.len() < 2 {
                return Err(r
                    .error(
                        at,
                        format!(
                            "a curve needs at least 2 points, this one has {}",
                            points.len()
                        ),
                    )
                    .into());
            }
            // Cubic B-spline through its end points: each end repeated twice more.
            let (first, last) = (points[0], points[points.len() - 1]);
            let mut cp = Vec::with_capacity(points.len() + 4);
            cp.extend_from_slice(&[first, first]);
            cp.extend_from_slice(&points);
            cp.extend_from_slice(&[last, last]);
            self.stats.shapes += 1;
            self.stats.curves += 1;
            let seq = self.seq;
            self.seq += 1;
            self.sink
                .shape(ShapeEvent {
                    seq,
                    kind: "curve".into(),
                    parent_from_shape: m,
                    reverse_orientation: false,
                    material: spec.material.clone(),
                    alpha_texture: None,
                    alpha: None,
                    alpha_image: None,
                    area_light: None,
                    object: inside,
                    element: Some(ctx.element),
                    source_path: None,
                    loc: input.loc(at),
                    geometry: Geometry::Curve(Curve {
                        basis: "bspline".into(),
                        curve_type: "flat".into(),
                        degree: 3,
                        control_points: cp,
                        width0: spec.width_root,
                        width1: spec.width_tip,
                        normals: None,
                    }),
                })
                .map_err(|e| Stop::Done(e.into()))
        });
        result
            .and_then(|()| r.finish().map_err(Stop::Json))
            .map_err(|s| input.stop(s))
    }
}
