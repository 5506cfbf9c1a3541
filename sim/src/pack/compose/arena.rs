//! LIBERO's arena (scene XML) as its problem class configures it.

use std::path::Path;

use super::error::ComposeError;
use super::xml::*;
use crate::cache::LiberoPack;

/// LIBERO's arena from the pack's scene XML: `<asset>` children and the `<worldbody>` children
/// (floor, walls, decorations, lights, the scene's own furniture).
#[derive(Debug, Clone, Default)]
pub struct ArenaXml {
    /// `<asset>` children.
    pub assets: String,
    /// `<worldbody>` children.
    pub world: String,
}

/// Reads the scene XML of `arena` as LIBERO's problem class configures it (libero.md §4.1): floor and
/// wall textures from the class's style, the scene's cameras left out (the composer places LIBERO's),
/// the robosuite `table` body left out (the composer builds it as robosuite's `TableArena` does), the
/// body named like the workspace renamed `<name>_arena` (the composer's workspace body carries the
/// regions), and colliding geoms given the environment's collision bits.
pub fn arena_xml(
    pack: &LiberoPack,
    arena: crate::world::scene::arena::Arena,
) -> Result<ArenaXml, ComposeError> {
    use crate::world::scene::arena::Arena;
    let (file, floor, wall) = match arena {
        Arena::Tabletop => (
            "libero_tabletop_base_style.xml",
            "light-gray-floor-tile.png",
            "light-gray-plaster.png",
        ),
        Arena::Kitchen => (
            "libero_kitchen_tabletop_base_style.xml",
            "gray_ceramic_tile.png",
            "yellow_linen_wall_texture.png",
        ),
        Arena::LivingRoom => (
            "libero_living_room_tabletop_base_style.xml",
            "seamless_wood_planks_floor.png",
            "light-gray-plaster.png",
        ),
        Arena::Study => (
            "libero_study_base_style.xml",
            "light-gray-floor-tile.png",
            "light-gray-plaster.png",
        ),
        Arena::Floor => (
            "libero_floor_base_style.xml",
            "light-gray-floor-tile.png",
            "light-gray-plaster.png",
        ),
        Arena::CoffeeTable => (
            "libero_coffee_table_base_style.xml",
            "seamless_wood_planks_floor.png",
            "light-gray-plaster.png",
        ),
    };
    let path = pack.assets_dir().join("scenes").join(file);
    let xml_err = |message: String| ComposeError::Xml {
        path: path.clone(),
        message,
    };
    let root = read_element(&path)?;
    let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let textures = pack.assets_dir().join("textures");
    let mut out = ArenaXml::default();
    for a in root.children.iter().filter(|c| c.tag == "asset") {
        for c in &a.children {
            let mut c = c.clone();
            let style = match (c.tag.as_str(), c.attr("name")) {
                ("texture", Some("texplane")) => Some(floor),
                ("texture", Some("tex-wall")) => Some(wall),
                _ => None,
            };
            let file = match style {
                Some(f) => Some(textures.join(f)),
                None => c.attr("file").map(|f| dir.join(f)),
            };
            if let Some(abs) = file {
                if !abs.exists() {
                    return Err(xml_err(format!("{} `{}` not found", c.tag, abs.display())));
                }
                c.set("file", abs.display().to_string());
            }
            c.write(&mut out.assets, 1);
        }
    }
    let ws = arena.workspace();
    for w in root.children.iter().filter(|c| c.tag == "worldbody") {
        for c in &w.children {
            if c.tag == "camera" || (c.tag == "body" && c.attr("name") == Some("table")) {
                continue;
            }
            let mut c = c.clone();
            if c.tag == "body" && c.attr("name") == Some(ws) {
                c.set("name", format!("{ws}_arena"));
            }
            arena_collision_bits(&mut c);
            c.write(&mut out.world, 1);
        }
    }
    Ok(out)
}
