//! Which branch of an `Or` goal the expert follows.

/// The rule that picks an `Or` goal's branch when every branch starts by putting an object in
/// or on something; both are rules the scene shows (unlike a draw from the seed).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BranchRule {
    /// The branch whose first object is nearest, in the table plane, to where it goes (T7: the
    /// bowl nearer the empty plate first). A relation of three objects.
    #[default]
    Destination,
    /// The branch whose first object is nearest to the gripper at the start (T7: the bowl nearer
    /// the hand first), ties (branches moving the same object first: T9/T10) broken by
    /// [`BranchRule::Destination`]. Each object's own offset to the hand decides.
    Gripper,
}

impl std::str::FromStr for BranchRule {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "destination" => Ok(BranchRule::Destination),
            "gripper" => Ok(BranchRule::Gripper),
            other => Err(format!(
                "branch rule `{other}`: expected `destination` or `gripper`"
            )),
        }
    }
}
