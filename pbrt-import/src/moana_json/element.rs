//! Elements: their materials, transform, copies and the body (geometry and primitives) placed under
//! each.

use std::path::Path;
use std::sync::Arc;

use super::json::Node;
use super::{Ctx, CurveSpec, Importer, Input, Materials};
use crate::events::{FileEvent, InstanceEvent, Material, ObjectEvent, Via};
use crate::math::{self, M64};
use crate::{ElementId, Error, Loc, Location, MaterialId, ObjectId};

impl Importer<'_> {
    pub(super) fn materials(
        &mut self,
        el: &Input,
        doc: &Node,
        element: (ElementId, &str),
    ) -> Result<Materials, Error> {
        let mut out = Materials::default();
        let Some(node) = doc.get("matFile") else {
            return Ok(out);
        };
        let Some(rel) = node.as_str() else {
            return Err(el.invalid(node.at, "matFile must be a path string"));
        };
        let path = self.resolve(rel, &el.path);
        let Some(input) = self.open(&path, Some(&el.location(node.at)), Some(element))? else {
            return Ok(out);
        };
        let tree = input.tree()?;
        if !tree.is_obj() {
            return Err(input.invalid(
                tree.at,
                "a materials file must be an object (name → material)",
            ));
        }
        for (name, m) in tree.members() {
            let color = |key: &str| -> Result<Option<[f32; 3]>, Error> {
                let Some(c) = m.get(key) else { return Ok(None) };
                let v: Vec<f64> = c.items().iter().filter_map(Node::as_f64).collect();
                if v.len() < 3 || v[..3].iter().any(|x| !x.is_finite()) {
                    return Err(input.invalid(c.at, format!("{key} must be 3 finite numbers")));
                }
                Ok(Some([v[0] as f32, v[1] as f32, v[2] as f32]))
            };
            let scalar = |key: &str| m.get(key).and_then(Node::as_f64).filter(|x| x.is_finite());
            let material = Arc::new(Material {
                id: MaterialId(self.next_material),
                name: Some(format!("{}/{name}", element.1)),
                kind: m
                    .get("type")
                    .and_then(Node::as_str)
                    .unwrap_or("disney")
                    .to_string(),
                base_color: color("baseColor")?,
                base_color_texture: None,
                opacity: None,
                base_color_image: None,
                ptex: None,
                roughness: scalar("roughness").map(|r| r.clamp(0.0, 1.0) as f32),
                metallic: scalar("metallic").map(|r| r.clamp(0.0, 1.0) as f32),
                loc: input.loc(m.at),
            });
            self.next_material += 1;
            self.sink.material(&material)?;
            if let Some(dir) = m
                .get("colorMap")
                .and_then(Node::as_str)
                .filter(|s| !s.is_empty())
            {
                out.ptex_dirs
                    .insert(material.id, self.resolve(dir, &input.path));
            }
            for a in m.get("assignment").map(Node::items).unwrap_or_default() {
                if let Some(p) = a.as_str() {
                    out.by_primitive.insert(p.to_string(), material.clone());
                }
            }
            out.by_name.insert(name.clone(), material);
        }
        Ok(out)
    }

    pub(super) fn element(
        &mut self,
        path: &Path,
        id: ElementId,
        referenced_at: Option<&Location>,
    ) -> Result<(), Error> {
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "element".into());
        // The element's name is known only once the file is read; the stem names it (Moana's
        // files are `<name>/<name>.json`).
        let Some(input) = self.open(path, referenced_at, Some((id, &stem)))? else {
            return Ok(());
        };
        let doc = input.tree()?;
        let keys = [
            "geomObjFile",
            "instancedPrimitiveJsonFiles",
            "instancedCopies",
        ];
        if !doc.is_obj() || keys.iter().all(|k| doc.get(k).is_none()) {
            return Err(input.invalid(
                doc.at,
                "not a Moana element file (an object with geomObjFile, instancedPrimitiveJsonFiles or instancedCopies) nor a scene list (an object with elements)",
            ));
        }
        let name = stem.as_str();
        let mats = self.materials(&input, &doc, (id, name))?;
        let world_from_element =
            Self::matrix(&input, doc.get("transformMatrix"), "transformMatrix")?;
        let copies: &[(String, Node)] = doc
            .get("instancedCopies")
            .map(Node::members)
            .unwrap_or_default();
        let instanced = copies.iter().any(|(_, c)| c.get("geomObjFile").is_none());
        let ctx = Ctx {
            element: id,
            name,
            mats: &mats,
        };
        if instanced {
            let object = self.new_object();
            self.sink.object_begin(&ObjectEvent {
                object,
                name,
                element: Some(id),
                loc: input.loc(doc.at),
            })?;
            self.body(&input, &doc, &math::IDENTITY, Some(object), &ctx)?;
            self.sink.object_end(&ObjectEvent {
                object,
                name,
                element: Some(id),
                loc: input.loc(doc.at),
            })?;
            self.instance(
                object,
                name,
                &world_from_element,
                None,
                id,
                input.loc(doc.at),
            )?;
            for (copy, c) in copies {
                if c.get("geomObjFile").is_none() {
                    let m = Self::matrix(
                        &input,
                        c.get("transformMatrix"),
                        &format!("instancedCopies.{copy}.transformMatrix"),
                    )?;
                    self.instance(object, name, &m, None, id, input.loc(c.at))?;
                }
            }
        } else {
            self.body(&input, &doc, &world_from_element, None, &ctx)?;
        }
        // Copies with geometry of their own (the release's coral).
        for (copy, c) in copies {
            if c.get("geomObjFile").is_some() {
                let m = Self::matrix(
                    &input,
                    c.get("transformMatrix"),
                    &format!("instancedCopies.{copy}.transformMatrix"),
                )?;
                self.body(&input, c, &m, None, &ctx)?;
            }
        }
        self.sink.file_exit(&FileEvent {
            file: input.file,
            path: &input.path,
            depth: 1,
            via: Via::Include,
            from_entry_world: true,
            element: Some(id),
            element_name: Some(name),
            size_bytes: input.bytes.bytes().len() as u64,
        })?;
        Ok(())
    }

    pub(super) fn new_object(&mut self) -> ObjectId {
        let o = ObjectId(self.next_object);
        self.next_object += 1;
        self.stats.objects += 1;
        o
    }

    pub(super) fn instance(
        &mut self,
        object: ObjectId,
        name: &str,
        parent_from_instance: &M64,
        inside: Option<ObjectId>,
        element: ElementId,
        loc: Loc,
    ) -> Result<(), Error> {
        self.stats.instances += 1;
        self.sink.object_instance(&InstanceEvent {
            object,
            name,
            parent_from_instance: math::to_f32(parent_from_instance),
            inside,
            element: Some(element),
            loc,
        })?;
        Ok(())
    }

    /// An element's (or a copy's) geometry and primitives under `base`.
    pub(super) fn body(
        &mut self,
        input: &Input,
        node: &Node,
        base: &M64,
        inside: Option<ObjectId>,
        ctx: &Ctx<'_>,
    ) -> Result<(), Error> {
        let prims: &[(String, Node)] = node
            .get("instancedPrimitiveJsonFiles")
            .map(Node::members)
            .unwrap_or_default();
        // 1. The archives as objects.
        for (_, p) in prims {
            if p.get("type").and_then(Node::as_str) != Some("archive") {
                continue;
            }
            for a in p.get("archives").map(Node::items).unwrap_or_default() {
                let Some(rel) = a.as_str() else {
                    return Err(input.invalid(a.at, "archives must be a list of OBJ paths"));
                };
                let path = self.resolve(rel, &input.path);
                self.archive_object(&path, Some(&input.location(a.at)), ctx)?;
            }
        }
        // 2. The element's own geometry.
        if let Some(g) = node.get("geomObjFile") {
            let Some(rel) = g.as_str() else {
                return Err(input.invalid(g.at, "geomObjFile must be a path string"));
            };
            let path = self.resolve(rel, &input.path);
            self.obj_shapes(&path, Some(&input.location(g.at)), inside, base, ctx)?;
        }
        // 3. Placements and curves, in the file's order.
        for (prim, p) in prims {
            let kind = p.get("type").and_then(Node::as_str).unwrap_or("");
            let Some(file) = p.get("jsonFile") else {
                self.warn(
                    Some(input.loc(p.at)),
                    format!("primitive `{prim}` names no jsonFile; skipped"),
                );
                continue;
            };
            let Some(rel) = file.as_str() else {
                return Err(input.invalid(file.at, "jsonFile must be a path string"));
            };
            let path = self.resolve(rel, &input.path);
            let at = input.location(file.at);
            match kind {
                "archive" => self.archive_placements(&path, &at, base, inside, ctx)?,
                "curve" => {
                    let width = |k: &str| p.get(k).and_then(Node::as_f64).unwrap_or(0.01) as f32;
                    let material = ctx
                        .mats
                        .by_primitive
                        .get(prim)
                        .cloned()
                        .unwrap_or_else(|| self.default_material.clone());
                    let curve = CurveSpec {
                        width_root: width("widthRoot"),
                        width_tip: width("widthTip"),
                        material,
                    };
                    self.curves(&path, &at, base, inside, ctx, &curve)?;
                }
                other => self.warn(
                    Some(input.loc(p.at)),
                    format!("primitive `{prim}` has type `{other}` (archive and curve are read); skipped"),
                ),
            }
        }
        Ok(())
    }
}
