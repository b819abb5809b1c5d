//! Graphics state: the current transform (CTM) and its stacks, attribute/transform/object
//! blocks, and cameras (emitted once the world begins).

use super::*;

impl<'s> Parser<'s> {
    pub(super) fn apply(&mut self, m: M64) {
        for i in 0..2 {
            if self.xs.active & (1 << i) != 0 {
                self.xs.ctm[i] = math::mul(&self.xs.ctm[i], &m);
            }
        }
    }

    pub(super) fn set(&mut self, m: M64) {
        for i in 0..2 {
            if self.xs.active & (1 << i) != 0 {
                self.xs.ctm[i] = m;
            }
        }
    }

    pub(super) fn require_world(&mut self, tok: &Token<'_>) {
        if !self.in_world {
            let name = String::from_utf8_lossy(tok.bytes).into_owned();
            self.warn_once(
                &format!("world:{name}"),
                Some(tok.loc),
                format!("{name} before WorldBegin"),
            );
        }
    }

    pub(super) fn pop_block(&mut self, tok: &Token<'_>, kind: BlockKind) -> Result<()> {
        let Some(&(top, _)) = self.blocks.last() else {
            let what = String::from_utf8_lossy(tok.bytes);
            return Err(self.err(
                tok,
                ParseErrorKind::Unbalanced(format!("{what} without a matching begin")),
            ));
        };
        // pbrt-v3 keeps separate attribute and transform stacks and lets ObjectBegin/End
        // interleave with AttributeBegin/End; pbrt-v4 requires proper nesting.
        if top != kind && (self.v4() || kind == BlockKind::Transform || top == BlockKind::Transform)
        {
            let what = String::from_utf8_lossy(tok.bytes);
            return Err(self.err(
                tok,
                ParseErrorKind::Unbalanced(format!("{what} closes {}", top.begin())),
            ));
        }
        self.blocks.pop();
        match kind {
            BlockKind::Transform => self.pop_xform(),
            BlockKind::Attribute | BlockKind::Object => {
                if let Some(g) = self.attr_stack.pop() {
                    self.gs = g;
                    self.pop_xform();
                }
            }
        }
        Ok(())
    }

    /// Save the transform state. `XState` is 264 bytes and this runs twice per
    /// `AttributeBegin`/`End` pair: copy it once, straight into the stack's slot.
    #[inline]
    pub(super) fn push_xform(&mut self) {
        self.xform_stack
            .extend_from_slice(std::slice::from_ref(&self.xs));
    }

    /// Restore the saved transform state (one copy, from the stack's slot).
    #[inline]
    fn pop_xform(&mut self) {
        if let Some(x) = self.xform_stack.last() {
            self.xs = *x;
            self.xform_stack.truncate(self.xform_stack.len() - 1);
        }
    }

    // ---- cameras and lights -------------------------------------------------------------

    pub(super) fn camera<'b>(&mut self, lx: &mut Lexer<'b>, tok: &Token<'b>) -> Result<()> {
        let (kind, _) = self.string(lx, tok)?;
        let p = self.params(lx)?;
        self.require_finite("Camera", &p)?;
        if kind == "perspective" {
            // A field of view of 0 (or ≥ 180) degrees makes every ray the same: a flat image.
            if let Some(param) = p.get("fov") {
                let fov = p.float("fov").unwrap_or(90.0);
                if !(fov > 0.0 && fov < 180.0) {
                    return Err(self.err_at(
                        param.loc,
                        param.name,
                        ParseErrorKind::BadParameter(format!(
                            "Camera \"perspective\" \"float fov\" is {fov} degrees: it must be more than 0 and less than 180"
                        )),
                    ));
                }
            }
        }
        if self.in_world {
            self.warn(Some(tok.loc), "Camera inside the world block".into());
        }
        let camera_from_world = self.xs.ctm[0];
        if let Some(inv) = math::inverse(&camera_from_world) {
            self.named_coords.insert("camera".into(), [inv; 2]);
        }
        let sw = p
            .nums("screenwindow")
            .filter(|v| v.len() == 4)
            .map(|v| [v[0], v[1], v[2], v[3]]);
        self.cameras.push(PendingCamera {
            fov_deg: (kind == "perspective").then(|| p.float("fov").unwrap_or(90.0)),
            kind: kind.into_owned(),
            camera_from_world,
            screen_window: sw,
            lens_radius: p.float("lensradius").unwrap_or(0.0),
            focal_distance: p.float("focaldistance"),
            loc: tok.loc,
        });
        Ok(())
    }

    pub(super) fn emit_cameras(&mut self) -> Result<()> {
        for c in std::mem::take(&mut self.cameras) {
            let world_from_camera = match math::inverse(&c.camera_from_world) {
                Some(m) => m,
                None => {
                    self.warn(Some(c.loc), "singular camera transform".into());
                    math::IDENTITY
                }
            };
            self.stats.cameras += 1;
            let ev = CameraEvent {
                kind: c.kind,
                camera_from_world: math::to_f32(&c.camera_from_world),
                world_from_camera: math::to_f32(&world_from_camera),
                fov_deg: c.fov_deg,
                screen_window: c.screen_window,
                lens_radius: c.lens_radius,
                focal_distance: c.focal_distance,
                resolution: self.film_resolution,
                path: self
                    .stats
                    .files
                    .get(c.loc.file.0 as usize)
                    .map(PathBuf::as_path)
                    .unwrap_or(Path::new("")),
                loc: c.loc,
            };
            self.sink.camera(&ev)?;
        }
        Ok(())
    }
}
