//! Object definitions and instances: `ObjectBegin`/`ObjectEnd`, `ObjectInstance`, forward
//! references resolved at the end.

use super::*;

impl<'s> Parser<'s> {
    pub(super) fn object_begin<'b>(&mut self, lx: &mut Lexer<'b>, tok: &Token<'b>) -> Result<()> {
        self.require_world(tok);
        let (name, ntok) = self.string(lx, tok)?;
        if self.current_object.is_some() {
            return Err(self.err(
                tok,
                ParseErrorKind::Misplaced("ObjectBegin inside an object definition".into()),
            ));
        }
        self.attr_stack.push(self.gs.clone());
        self.push_xform();
        self.blocks.push((BlockKind::Object, tok.loc));
        let id = match self.objects.get(name.as_ref()).copied() {
            Some(id) if self.object_defined[id.0 as usize] => {
                if self.v4() {
                    return Err(self.err(&ntok, ParseErrorKind::Invalid("object redefined".into())));
                }
                self.warn(
                    Some(ntok.loc),
                    format!("object \"{name}\" redefined; the later definition wins"),
                );
                self.new_object(&name)
            }
            Some(id) => id,
            None => self.new_object(&name),
        };
        self.object_defined[id.0 as usize] = true;
        self.current_object = Some(id);
        self.stats.objects += 1;
        self.sink.object_begin(&ObjectEvent {
            object: id,
            name: &name,
            element: self.element,
            loc: tok.loc,
        })?;
        Ok(())
    }

    pub(super) fn new_object(&mut self, name: &str) -> ObjectId {
        // A (v3) redefinition gives the name a new id.
        self.last_instance = None;
        let id = ObjectId(self.object_names.len() as u32);
        self.object_names.push(name.to_owned());
        self.object_defined.push(false);
        self.objects.insert(name.to_owned(), id);
        id
    }

    pub(super) fn object_instance<'b>(
        &mut self,
        lx: &mut Lexer<'b>,
        tok: &Token<'b>,
    ) -> Result<()> {
        self.require_world(tok);
        // Instance-heavy files name the same object over and over: compare the raw token
        // with the last one instead of unescaping, validating and hashing it again.
        let mut peek = lx.clone();
        if let (Ok(Some(t)), Some((raw, id))) = (peek.next_token(), &self.last_instance) {
            if t.kind == TokenKind::String
                && t.bytes == raw.as_slice()
                && self.current_object != Some(*id)
            {
                let id = *id;
                *lx = peek;
                return self.emit_instance(id, tok);
            }
        }
        let (name, ntok) = self.string(lx, tok)?;
        let id = match self.objects.get(name.as_ref()).copied() {
            Some(id) => {
                self.last_instance = Some((ntok.bytes.to_vec(), id));
                id
            }
            None if self.v4() => {
                // pbrt-v4 resolves instances after parsing: forward references are legal.
                let id = self.new_object(&name);
                self.forward_refs.push((id, ntok.loc, name.to_string()));
                id
            }
            None => return Err(self.err(&ntok, ParseErrorKind::UnknownObject)),
        };
        if Some(id) == self.current_object {
            return Err(self.err(
                &ntok,
                ParseErrorKind::Invalid("object instances itself".into()),
            ));
        }
        self.emit_instance(id, tok)
    }

    fn emit_instance(&mut self, id: ObjectId, tok: &Token<'_>) -> Result<()> {
        let parent_from_instance = math::to_f32(&self.xs.ctm[0]);
        self.emit_instance_at(id, parent_from_instance, self.current_object, tok.loc)
    }

    /// Counts and emits one instance of object `id` (named by its definition).
    pub(super) fn emit_instance_at(
        &mut self,
        id: ObjectId,
        parent_from_instance: crate::Mat4,
        inside: Option<ObjectId>,
        loc: Loc,
    ) -> Result<()> {
        self.stats.instances += 1;
        if let Some(parent) = inside {
            self.instance_edges.entry((parent.0, id.0)).or_insert(loc);
        }
        let ev = InstanceEvent {
            object: id,
            name: self
                .object_names
                .get(id.0 as usize)
                .map_or("", String::as_str),
            parent_from_instance,
            inside,
            element: self.element,
            loc,
        };
        self.sink.object_instance(&ev)?;
        Ok(())
    }

    /// The first instancing cycle among objects, if any: the `ObjectInstance` that closes it
    /// and the object names along it (first and last the same).
    pub(super) fn instance_cycle(&self) -> Option<(Loc, Vec<String>)> {
        let mut children: std::collections::BTreeMap<u32, Vec<u32>> = Default::default();
        for &(p, c) in self.instance_edges.keys() {
            children.entry(p).or_default().push(c);
        }
        // 0: unseen, 1: on the current path, 2: done. Iterative DFS (scenes nest deeply).
        let mut state: std::collections::HashMap<u32, u8> = Default::default();
        for &root in children.keys() {
            if state.get(&root).copied().unwrap_or(0) != 0 {
                continue;
            }
            let mut stack: Vec<(u32, usize)> = vec![(root, 0)];
            state.insert(root, 1);
            while let Some(&mut (node, ref mut next)) = stack.last_mut() {
                let kids = children.get(&node).map_or(&[][..], Vec::as_slice);
                if let Some(&child) = kids.get(*next) {
                    *next += 1;
                    match state.get(&child).copied().unwrap_or(0) {
                        0 => {
                            state.insert(child, 1);
                            stack.push((child, 0));
                        }
                        1 => {
                            let at = stack.iter().position(|&(n, _)| n == child)?;
                            let name = |id: u32| {
                                self.object_names
                                    .get(id as usize)
                                    .cloned()
                                    .unwrap_or_default()
                            };
                            let mut names: Vec<String> =
                                stack[at..].iter().map(|&(n, _)| name(n)).collect();
                            names.push(name(child));
                            let loc = *self.instance_edges.get(&(node, child))?;
                            return Some((loc, names));
                        }
                        _ => {}
                    }
                } else {
                    state.insert(node, 2);
                    stack.pop();
                }
            }
        }
        None
    }
}
