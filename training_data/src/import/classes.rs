//! The class list of an imported set.
//!
//! A dataset carries its own classes: any number, any names. By default an import keeps
//! the source's classes ([`ClassList::Source`]), in the order the source declares them
//! (COCO: by category id; formats without a declaration: by first appearance). A
//! [`ClassMap`] renames or merges source classes first; with `drop_unmapped` only the
//! mapped ones are kept. [`ClassList::Signs`] imports onto the synthetic generator's ten
//! signs instead (to fine-tune a synthetic-trained detector on real sign photos), and
//! [`ClassList::Names`] onto a list of the user's own; a class outside either is an
//! error naming the record, unless unmapped classes are dropped.
//!
//! What the drone does on a class (turn, stop, wait, nothing) is a separate, optional
//! mapping from class name to [`NavAction`]; the ten signs bring their own.
use crate::{ClassId, ClassInfo, DataError, NavAction, Sign};
use std::collections::BTreeMap;
use std::path::Path;

/// Which class list an import produces.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum ClassList {
    /// The source's own classes (after the class map).
    #[default]
    Source,
    /// The synthetic generator's ten signs (matched by name or road sign code).
    Signs,
    /// These names, in this order.
    Names(Vec<String>),
}

impl ClassList {
    /// `source`, `signs`, or a file with one class name per line (or a JSON list).
    pub fn parse(arg: &str) -> Result<ClassList, DataError> {
        match arg {
            "source" => Ok(ClassList::Source),
            "signs" => Ok(ClassList::Signs),
            file => {
                let path = Path::new(file);
                let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
                let names: Vec<String> = if text.trim_start().starts_with('[') {
                    serde_json::from_str(&text).map_err(|e| DataError::json(path, e))?
                } else {
                    text.lines()
                        .map(str::trim)
                        .filter(|l| !l.is_empty() && !l.starts_with('#'))
                        .map(str::to_owned)
                        .collect()
                };
                if names.is_empty() {
                    return Err(DataError::invalid(path, "class list", "names no class"));
                }
                let mut seen = std::collections::BTreeSet::new();
                for n in &names {
                    if !seen.insert(n.as_str()) {
                        return Err(DataError::invalid(
                            path,
                            format!("class {n:?}"),
                            "is listed twice",
                        ));
                    }
                }
                Ok(ClassList::Names(names))
            }
        }
    }
}

/// A map from source class (name, or numeric id as a string) to the class it becomes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ClassMap {
    map: BTreeMap<String, String>,
}

/// Read a JSON (or `.toml`) object `{"source class": "class name"}`.
pub fn read_class_map(path: &Path) -> Result<BTreeMap<String, String>, DataError> {
    let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
    if path.extension().is_some_and(|e| e == "toml") {
        toml::from_str(&text).map_err(|e| DataError::Config {
            path: path.to_owned(),
            message: e.to_string(),
        })
    } else {
        serde_json::from_str(&text).map_err(|e| DataError::json(path, e))
    }
}

impl ClassMap {
    /// Read a JSON (or `.toml`) object `{"source class": "class name"}`.
    pub fn from_file(path: &Path) -> Result<Self, DataError> {
        Ok(Self {
            map: read_class_map(path)?,
        })
    }

    /// A map from pairs.
    pub fn from_pairs<'a>(pairs: impl IntoIterator<Item = (&'a str, &'a str)>) -> Self {
        Self {
            map: pairs
                .into_iter()
                .map(|(k, v)| (k.to_owned(), v.to_owned()))
                .collect(),
        }
    }

    /// Whether no class is mapped.
    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }

    /// The class a source class becomes: the map's entry for its name, else for its
    /// numeric id, else `None`.
    pub fn get(&self, name: &str, id: Option<u64>) -> Option<&str> {
        self.map
            .get(name)
            .or_else(|| id.and_then(|i| self.map.get(&i.to_string())))
            .map(String::as_str)
    }
}

/// The classes of an import as they are met: source class → class id.
#[derive(Debug)]
pub(crate) struct ClassTable {
    list: ClassList,
    map: ClassMap,
    drop_unmapped: bool,
    /// Names in id order (for `Source`, grown as classes are met).
    names: Vec<String>,
    /// Road sign codes the source gives (frugal's own COCO exports), by class name.
    codes: BTreeMap<String, String>,
}

impl ClassTable {
    pub(crate) fn new(list: &ClassList, map: &ClassMap, drop_unmapped: bool) -> Self {
        let names = match list {
            ClassList::Source => Vec::new(),
            ClassList::Signs => Sign::ALL.iter().map(|s| s.name().to_owned()).collect(),
            ClassList::Names(n) => n.clone(),
        };
        Self {
            list: list.clone(),
            map: map.clone(),
            drop_unmapped,
            names,
            codes: BTreeMap::new(),
        }
    }

    /// Keep the code a source gives for the class `id` (frugal's COCO `code` extra).
    pub(crate) fn note_code(&mut self, id: ClassId, code: &str) {
        if let Some(name) = self.names.get(usize::from(id)) {
            self.codes.insert(name.clone(), code.to_owned());
        }
    }

    /// The class id of a source class, `None` when it is dropped; `path` and `record`
    /// name the annotation for the error of an unknown class.
    pub(crate) fn resolve(
        &mut self,
        path: &Path,
        record: &str,
        name: &str,
        id: Option<u64>,
    ) -> Result<Option<ClassId>, DataError> {
        let mapped = self.map.get(name, id);
        if mapped.is_none() && self.drop_unmapped && !self.map.is_empty() {
            return Ok(None);
        }
        let target = mapped.unwrap_or(name);
        let found = match &self.list {
            ClassList::Source => match self.names.iter().position(|n| n == target) {
                Some(i) => Some(i),
                None => {
                    self.names.push(target.to_owned());
                    Some(self.names.len() - 1)
                }
            },
            ClassList::Signs => Sign::from_name(target).map(|s| usize::from(s.id())),
            ClassList::Names(n) => n.iter().position(|x| x == target),
        };
        match found {
            Some(i) => ClassId::try_from(i)
                .map(Some)
                .map_err(|_| DataError::invalid(path, record, "more than 65,536 classes")),
            None if self.drop_unmapped => Ok(None),
            None => Err(DataError::UnknownClass {
                path: path.to_owned(),
                record: record.to_owned(),
                class: target.to_owned(),
            }),
        }
    }

    /// The final class list with each class's navigation meaning: the signs' own, then
    /// `actions` (class name → action), which must name existing classes (`what` names
    /// the actions' source for that error).
    pub(crate) fn finish(
        self,
        actions: &BTreeMap<String, NavAction>,
        what: &Path,
    ) -> Result<Vec<crate::ClassInfo>, DataError> {
        for name in actions.keys() {
            if !self.names.contains(name) {
                return Err(DataError::invalid(
                    what,
                    format!("action for {name:?}"),
                    format!("no such class; the classes are {}", self.names.join(", ")),
                ));
            }
        }
        Ok(self
            .names
            .iter()
            .enumerate()
            .map(|(i, name)| {
                let sign = matches!(self.list, ClassList::Signs)
                    .then(|| Sign::from_name(name))
                    .flatten();
                ClassInfo {
                    id: i as ClassId,
                    name: name.clone(),
                    code: sign
                        .map(|s| s.code().to_owned())
                        .or_else(|| self.codes.get(name).cloned())
                        .unwrap_or_default(),
                    action: actions
                        .get(name)
                        .copied()
                        .or_else(|| sign.and_then(Sign::action)),
                }
            })
            .collect())
    }
}

/// Parse `NAME=ACTION` (`turn_left`, `turn_right`, `stop`, `wait`).
pub fn parse_action(arg: &str) -> Result<(String, NavAction), String> {
    let (name, action) = arg
        .split_once('=')
        .ok_or_else(|| format!("{arg:?}: expected CLASS=ACTION, e.g. pedestrian=wait"))?;
    let action = NavAction::from_name(action.trim()).ok_or_else(|| {
        format!("{arg:?}: unknown action {action:?} (turn_left, turn_right, stop or wait)")
    })?;
    Ok((name.trim().to_owned(), action))
}
