//! Word-level text vocabulary (model.md §8, tiny config): lower-case alphanumeric words,
//! id 0 = padding, id 1 = unknown.

/// Padding id.
pub const PAD: u32 = 0;
/// Unknown-word id.
pub const UNK: u32 = 1;

/// Splits text into lower-case alphanumeric words (`"Put the bowl_1 on"` → put, the, bowl, 1, on).
pub fn words(text: &str) -> impl Iterator<Item = String> + '_ {
    text.split(|c: char| !c.is_alphanumeric())
        .filter(|w| !w.is_empty())
        .map(|w| w.to_lowercase())
}

/// A word vocabulary: `words()[i]` has id `i`; ids 0 and 1 are `<pad>` and `<unk>`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Vocab {
    words: Vec<String>,
    ids: std::collections::HashMap<String, u32>,
}

impl Vocab {
    /// Builds a sorted vocabulary from texts (deterministic: same texts → same ids).
    pub fn build<'a>(texts: impl IntoIterator<Item = &'a str>) -> Vocab {
        let mut set = std::collections::BTreeSet::new();
        for t in texts {
            set.extend(words(t));
        }
        let mut all = vec!["<pad>".to_string(), "<unk>".to_string()];
        all.extend(set);
        Vocab::from_words(all)
    }

    /// Rebuilds from a stored word list (index 0 must be `<pad>`, 1 `<unk>`).
    pub fn from_words(words: Vec<String>) -> Vocab {
        let ids = words
            .iter()
            .enumerate()
            .map(|(i, w)| (w.clone(), i as u32))
            .collect();
        Vocab { words, ids }
    }

    /// The words, by id.
    pub fn words(&self) -> &[String] {
        &self.words
    }

    /// Vocabulary size (including pad and unk).
    pub fn len(&self) -> usize {
        self.words.len()
    }

    /// True if only pad/unk exist.
    pub fn is_empty(&self) -> bool {
        self.words.len() <= 2
    }

    /// Token ids of `text` padded/truncated to `max_len`, and the mask (true = real token).
    pub fn encode(&self, text: &str, max_len: usize) -> (Vec<u32>, Vec<bool>) {
        let mut ids: Vec<u32> = words(text)
            .map(|w| self.ids.get(&w).copied().unwrap_or(UNK))
            .take(max_len)
            .collect();
        let n = ids.len();
        ids.resize(max_len, PAD);
        let mask = (0..max_len).map(|i| i < n).collect();
        (ids, mask)
    }
}
