//! Object categories as BDDL names them: the workspace categories the arena provides, and the
//! closed set of categories whose facts this crate knows ([`Category`]); any other name (LIBERO's
//! pack has dozens) is read from the pack and gets generic facts.

/// Categories LIBERO does not load as assets because the arena provides them (libero.md §1.1); an
/// instance of one of these is the workspace (`main_table - table`, `kitchen_table - kitchen_table`, …).
pub const WORKSPACE_CATEGORIES: [&str; 6] = [
    "table",
    "kitchen_table",
    "living_room_table",
    "study_table",
    "floor",
    "coffee_table",
];

/// A category whose facts the crate knows: the built-in asset library's objects and fixtures (and
/// `white_cabinet`, which LIBERO's tasks name like the wooden one). Facts about the physical asset
/// (extent, footprint, grasp, place heights) are fields of its `world::assets::AssetDef`; the words
/// for goal texts are here. A new category is a new variant: every `match` on it then asks for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Category {
    /// `akita_black_bowl`.
    AkitaBlackBowl,
    /// `plate`.
    Plate,
    /// `basket`.
    Basket,
    /// `cream_cheese`.
    CreamCheese,
    /// `wine_bottle`.
    WineBottle,
    /// `wine_rack` (fixture).
    WineRack,
    /// `flat_stove` (fixture).
    FlatStove,
    /// `wooden_cabinet` (fixture).
    WoodenCabinet,
    /// `white_cabinet` (fixture; LIBERO's pack only).
    WhiteCabinet,
}

impl Category {
    /// Every known category.
    pub const ALL: [Category; 9] = [
        Category::AkitaBlackBowl,
        Category::Plate,
        Category::Basket,
        Category::CreamCheese,
        Category::WineBottle,
        Category::WineRack,
        Category::FlatStove,
        Category::WoodenCabinet,
        Category::WhiteCabinet,
    ];

    /// The BDDL name (`akita_black_bowl`, …).
    pub const fn name(self) -> &'static str {
        match self {
            Category::AkitaBlackBowl => "akita_black_bowl",
            Category::Plate => "plate",
            Category::Basket => "basket",
            Category::CreamCheese => "cream_cheese",
            Category::WineBottle => "wine_bottle",
            Category::WineRack => "wine_rack",
            Category::FlatStove => "flat_stove",
            Category::WoodenCabinet => "wooden_cabinet",
            Category::WhiteCabinet => "white_cabinet",
        }
    }

    /// The category of a BDDL name, `None` for one the crate has no facts for.
    pub fn from_name(name: &str) -> Option<Category> {
        Category::ALL.into_iter().find(|c| c.name() == name)
    }

    /// The short words goal texts use (`bowl`, `bottle`, `cabinet`, …).
    pub const fn short_name(self) -> &'static str {
        match self {
            Category::AkitaBlackBowl => "bowl",
            Category::Plate => "plate",
            Category::Basket => "basket",
            Category::CreamCheese => "cream cheese",
            Category::WineBottle => "bottle",
            Category::WineRack => "rack",
            Category::FlatStove => "stove",
            Category::WoodenCabinet | Category::WhiteCabinet => "cabinet",
        }
    }
}

/// The short words for any category name: a known category's [`Category::short_name`], else the
/// name's words (`alphabet_soup` → `alphabet soup`).
pub fn short_words(name: &str) -> String {
    match Category::from_name(name) {
        Some(c) => c.short_name().to_string(),
        None => name.replace('_', " "),
    }
}
