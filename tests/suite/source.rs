//! Rust source read as text by the checks on the code itself (layers, sizes): comments,
//! strings and character literals blanked so that neither the paths nor the braces inside
//! them count.

/// `src` with the insides of comments, strings and character literals turned to spaces,
/// newlines kept, so that byte offsets and line numbers stay those of `src`.
pub(crate) fn blank(src: &str) -> Vec<u8> {
    let s = src.as_bytes();
    let mut out = s.to_vec();
    let clear = |out: &mut Vec<u8>, from: usize, to: usize| {
        for b in &mut out[from..to.min(s.len())] {
            if *b != b'\n' {
                *b = b' ';
            }
        }
    };
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let mut i = 0;
    while i < s.len() {
        let rest = &s[i..];
        let raw = match rest {
            [b'b', b'r', ..] => 2,
            [b'r', ..] => 1,
            _ => 0,
        };
        let hashes = rest[raw..].iter().take_while(|&&c| c == b'#').count();
        let after_ident = i > 0 && ident(s[i - 1]);
        if rest.starts_with(b"//") {
            let end = i + rest.iter().position(|&c| c == b'\n').unwrap_or(rest.len());
            clear(&mut out, i, end);
            i = end;
        } else if rest.starts_with(b"/*") {
            let mut depth = 0usize;
            let start = i;
            while i < s.len() {
                if s[i..].starts_with(b"/*") {
                    depth += 1;
                    i += 2;
                } else if s[i..].starts_with(b"*/") {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
            clear(&mut out, start, i);
        } else if raw > 0 && !after_ident && rest.get(raw + hashes) == Some(&b'"') {
            let close: Vec<u8> = std::iter::once(b'"')
                .chain(std::iter::repeat_n(b'#', hashes))
                .collect();
            let body = i + raw + hashes + 1;
            let end = s[body..]
                .windows(close.len())
                .position(|w| w == close.as_slice())
                .map_or(s.len(), |e| body + e + close.len());
            clear(&mut out, i, end);
            i = end;
        } else if rest[0] == b'"' {
            let start = i;
            i += 1;
            while i < s.len() && s[i] != b'"' {
                i += if s[i] == b'\\' { 2 } else { 1 };
            }
            i += 1;
            clear(&mut out, start, i);
        } else if rest[0] == b'\'' && rest.get(1) == Some(&b'\\') {
            let end = s
                .get(i + 3..)
                .and_then(|r| r.iter().position(|&c| c == b'\''))
                .map_or(s.len(), |e| i + 3 + e + 1);
            clear(&mut out, i, end);
            i = end;
        } else if rest[0] == b'\''
            && src[i + 1..]
                .chars()
                .next()
                .is_some_and(|c| s.get(i + 1 + c.len_utf8()) == Some(&b'\''))
        {
            let end = i + 2 + src[i + 1..].chars().next().map_or(1, char::len_utf8);
            clear(&mut out, i, end);
            i = end;
        } else {
            i += 1;
        }
    }
    out
}
