//! What a compositor selects by name (Cryptomatte): the glTF node that placed each mesh (the
//! "object") and each material, with stable names for the unnamed ones, and their IDs.
//!
//! Fallbacks: an unnamed node is `node<index>`, an unnamed material `material<index>` (glTF's
//! indices, so the name stays while the file does), and primitives without a material use
//! glTF's default material, named `default_material`. A node placing several primitives is
//! one object; nodes or materials of the same name share an ID, as the specification wants.

use crate::image::cryptomatte::id_of;

/// Name of glTF's default material (primitives that name none).
pub const DEFAULT_MATERIAL: &str = "default_material";

/// A node's name, or its fallback.
pub fn node_name(name: &str, index: usize) -> String {
    if name.is_empty() {
        format!("node{index}")
    } else {
        name.to_string()
    }
}

/// A material's name, or its fallback.
pub fn material_name(name: &str, index: usize) -> String {
    if name.is_empty() {
        format!("material{index}")
    } else {
        name.to_string()
    }
}

/// Object and material names with their Cryptomatte IDs.
#[derive(Clone, Debug, Default)]
pub struct Names {
    /// Per object (a placed mesh, copied or instanced: `SurfaceHit::object`): the node's name
    /// and its ID.
    pub objects: Vec<String>,
    pub object_ids: Vec<u32>,
    /// Per material (the scene's material index): its name and ID.
    pub materials: Vec<String>,
    pub material_ids: Vec<u32>,
}

impl Names {
    pub fn new(objects: Vec<String>, materials: Vec<String>) -> Names {
        Names {
            object_ids: objects.iter().map(|n| id_of(n)).collect(),
            material_ids: materials.iter().map(|n| id_of(n)).collect(),
            objects,
            materials,
        }
    }

    /// The object ID of an object (0, "nothing", for an index out of range).
    pub fn object_id(&self, object: u32) -> u32 {
        self.object_ids.get(object as usize).copied().unwrap_or(0)
    }

    pub fn material_id(&self, material: u32) -> u32 {
        self.material_ids.get(material as usize).copied().unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unnamed_things_get_their_index() {
        assert_eq!(node_name("", 4), "node4");
        assert_eq!(node_name("chair", 4), "chair");
        assert_eq!(material_name("", 0), "material0");
        let names = Names::new(vec!["a".into(), "a".into()], vec![DEFAULT_MATERIAL.into()]);
        assert_eq!(names.object_id(0), names.object_id(1));
        assert_eq!(names.object_id(0), id_of("a"));
        assert_eq!(names.object_id(7), 0);
        assert_eq!(names.material_id(0), id_of(DEFAULT_MATERIAL));
    }
}
