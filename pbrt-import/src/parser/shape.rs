//! The `Shape` directive: shape events in the current graphics state, and PLY meshes read in
//! parallel batches (the queue is flushed in document order).

use super::*;

impl<'s> Parser<'s> {
    pub(super) fn shape<'b>(&mut self, lx: &mut Lexer<'b>, tok: &Token<'b>) -> Result<()> {
        self.require_world(tok);
        let (kind, ktok) = self.string(lx, tok)?;
        let mut p = self.params(lx)?;
        let seq = self.next_seq;
        self.next_seq += 1;
        let mut material = self.gs.material.clone();
        if !self.v4()
            && ["Kd", "reflectance", "color", "Kr", "opacity", "roughness"]
                .iter()
                .any(|k| p.get(k).is_some())
        {
            // pbrt-v3: material parameters on a Shape override the current material's.
            let merged = ParamList {
                params: p
                    .params
                    .iter()
                    .filter(|q| !matches!(q.values, Values::Nums(ref v) if v.len() > 64))
                    .cloned()
                    .collect(),
                v4_spelling: false,
            };
            let derived = self.make_material(
                material.name.clone(),
                &material.kind.clone(),
                &merged,
                ktok.loc,
            );
            let keep_base = derived.base_color.is_none()
                || !["Kd", "reflectance", "color", "Kr"]
                    .iter()
                    .any(|k| p.get(k).is_some());
            let m = Material {
                base_color: if keep_base {
                    material.base_color
                } else {
                    derived.base_color
                },
                base_color_texture: if keep_base {
                    material.base_color_texture.clone()
                } else {
                    derived.base_color_texture.clone()
                },
                base_color_image: if keep_base {
                    material.base_color_image.clone()
                } else {
                    derived.base_color_image.clone()
                },
                ptex: if keep_base {
                    material.ptex.clone()
                } else {
                    derived.ptex.clone()
                },
                roughness: if p.get("roughness").is_some() {
                    derived.roughness
                } else {
                    material.roughness
                },
                metallic: material.metallic,
                opacity: derived.opacity.or(material.opacity),
                ..(*derived).clone()
            };
            material = Arc::new(m);
            self.sink.material(&material)?;
        }
        let mut event = ShapeEvent {
            seq,
            kind: String::new(),
            parent_from_shape: math::to_f32(&self.xs.ctm[0]),
            reverse_orientation: self.gs.reverse_orientation,
            material,
            alpha_texture: p.texture("alpha").map(str::to_owned),
            alpha: match p.get("alpha") {
                Some(param) if param.ty == ParamType::Texture => {
                    if self.image_of(param).is_some() {
                        None
                    } else {
                        self.color_of(param).map(|c| c.0[0])
                    }
                }
                _ => p.float("alpha"),
            },
            alpha_image: p
                .get("alpha")
                .and_then(|param| self.image_of(param))
                .map(|i| i.0),
            area_light: self.gs.area_light.clone(),
            object: self.current_object,
            element: self.element,
            source_path: None,
            loc: tok.loc,
            geometry: Geometry::Unsupported,
        };
        let segs = self.opts.tessellation_segments.max(3);
        let mut notes = Vec::new();
        let built: std::result::Result<Geometry, String> = match kind.as_ref() {
            "trianglemesh" => shapes::triangle_mesh(&mut p, &mut notes).map(Geometry::Mesh),
            "loopsubdiv" => {
                // The cage is used as it is; a negative level count is still said.
                if let Some(levels) = p.int("levels").filter(|&l| l < 0) {
                    notes.push(format!(
                        "\"integer levels\" is {levels}: a subdivision level count is 0 or more (the cage is used as it is)"
                    ));
                }
                shapes::triangle_mesh(&mut p, &mut notes).map(Geometry::Mesh)
            }
            "bilinearmesh" => {
                self.hint_v4("bilinearmesh");
                shapes::bilinear_mesh(&mut p, &mut notes).map(Geometry::Mesh)
            }
            "sphere" => shapes::sphere(&p, segs).map(Geometry::Mesh),
            "disk" => shapes::disk(&p, segs).map(Geometry::Mesh),
            "cylinder" => shapes::cylinder(&p, segs).map(Geometry::Mesh),
            "curve" => shapes::curve(&mut p).map(Geometry::Curve),
            "plymesh" => {
                event.kind = kind.into_owned();
                return self.plymesh(&p, &ktok, event);
            }
            other => {
                let known = matches!(
                    other,
                    "cone" | "paraboloid" | "hyperboloid" | "heightfield" | "nurbs"
                );
                let msg = if known {
                    "not converted"
                } else {
                    "unknown shape type"
                };
                self.warn_once(
                    &format!("shape:{other}"),
                    Some(ktok.loc),
                    format!("shape \"{other}\": {msg}; counted as unsupported"),
                );
                Ok(Geometry::Unsupported)
            }
        };
        for n in notes {
            self.warn(Some(ktok.loc), format!("{kind}: {n}"));
        }
        match built {
            Ok(g) => {
                event.kind = kind.into_owned();
                event.geometry = g;
                self.emit_shape(event)
            }
            Err(m) => {
                self.stats.skipped_shapes += 1;
                self.warn(Some(ktok.loc), format!("{kind}: {m}; shape skipped"));
                Ok(())
            }
        }
    }

    pub(super) fn emit_shape(&mut self, event: ShapeEvent) -> Result<()> {
        self.stats.shapes += 1;
        match &event.geometry {
            Geometry::Mesh(m) => self.stats.triangles += m.triangle_count() as u64,
            Geometry::Curve(_) => self.stats.curves += 1,
            Geometry::Unsupported => self.stats.unsupported_shapes += 1,
        }
        self.sink.shape(event)?;
        Ok(())
    }

    fn plymesh(
        &mut self,
        p: &ParamList<'_>,
        ktok: &Token<'_>,
        mut event: ShapeEvent,
    ) -> Result<()> {
        let Some(name) = p.string("filename") else {
            return Err(self.err(
                ktok,
                ParseErrorKind::BadParameter("plymesh needs \"string filename\"".into()),
            ));
        };
        if p.get("displacement").is_some() {
            self.warn_once(
                "displacement",
                Some(ktok.loc),
                "plymesh displacement recorded but not applied".into(),
            );
        }
        let path = self.resolve(name);
        let size = match crate::source::classify(&path) {
            crate::source::FileKind::Regular => std::fs::metadata(&path).map_or(0, |m| m.len()),
            crate::source::FileKind::Missing => {
                self.missing_file(path, ktok.loc);
                self.stats.skipped_shapes += 1;
                return Ok(());
            }
            crate::source::FileKind::Other(what) => {
                return Err(self.err(
                    ktok,
                    ParseErrorKind::Invalid(format!(
                        "plymesh: {} is {what}, not a PLY file",
                        path.display()
                    )),
                ))
            }
        };
        event.source_path = Some(path.clone());
        match self.opts.ply_loading {
            PlyLoading::Sequential => {
                self.stats.ply_bytes += size;
                let (mesh, report) = match crate::ply::read_ply_report(&path) {
                    Ok(r) => r,
                    Err(source) => {
                        return Err(Error::Ply {
                            path,
                            referenced_at: Box::new(self.location(ktok.loc)),
                            source: Box::new(source),
                        })
                    }
                };
                if let Some(w) = report.warning() {
                    self.warn(Some(ktok.loc), format!("{}: {w}", path.display()));
                }
                event.geometry = Geometry::Mesh(mesh);
                self.emit_shape(event)
            }
            PlyLoading::Parallel { batch_bytes } => {
                self.ply_queue.push(PendingPly { path, event });
                self.ply_queue_bytes += size;
                if self.ply_queue_bytes >= batch_bytes {
                    self.flush_plys()?;
                }
                Ok(())
            }
        }
    }

    /// Load the queued PLY files in parallel, then emit their shapes in queue order.
    pub(super) fn flush_plys(&mut self) -> Result<()> {
        if self.ply_queue.is_empty() {
            return Ok(());
        }
        let queue = std::mem::take(&mut self.ply_queue);
        self.stats.ply_bytes += self.ply_queue_bytes;
        self.ply_queue_bytes = 0;
        let _span = tracing::debug_span!("ply_batch", files = queue.len()).entered();
        let loaded: Vec<_> = queue
            .par_iter()
            .map(|job| crate::ply::read_ply_report(&job.path))
            .collect();
        for (job, mesh) in queue.into_iter().zip(loaded) {
            match mesh {
                Ok((m, report)) => {
                    if let Some(w) = report.warning() {
                        self.warn(Some(job.event.loc), format!("{}: {w}", job.path.display()));
                    }
                    let mut ev = job.event;
                    ev.geometry = Geometry::Mesh(m);
                    self.emit_shape(ev)?;
                }
                Err(source) => {
                    return Err(Error::Ply {
                        path: job.path,
                        referenced_at: Box::new(self.location(job.event.loc)),
                        source: Box::new(source),
                    });
                }
            }
        }
        Ok(())
    }
}
