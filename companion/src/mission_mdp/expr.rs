//! Probability/reward expressions in MDP params: numbers, named probabilities (`P_V3`), unary
//! minus, `+`, `-`, `*`, `/` and parentheses, e.g. `"1 - P_sys"`, `"P_sys * (1 - 0.1 * P_obs)"`,
//! `"10 * P_V3 - 2"`. Parsed once at load into a small arena; evaluation is allocation-free.

/// A compiled expression. Variables are slots into a caller-provided value slice.
#[derive(Debug, Clone, PartialEq)]
pub struct Expr {
    nodes: Vec<Node>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Node {
    Const(f64),
    Var(usize),
    Neg(usize),
    Add(usize, usize),
    Sub(usize, usize),
    Mul(usize, usize),
    Div(usize, usize),
}

impl Expr {
    /// Parse `text`; `slot` maps a name to its variable slot (or `None` if the name is unknown).
    pub fn parse(text: &str, slot: &mut dyn FnMut(&str) -> Option<usize>) -> Result<Self, String> {
        let mut p = Parser {
            s: text.as_bytes(),
            i: 0,
            nodes: Vec::new(),
            slot,
        };
        let root = p.expr(0)?;
        p.ws();
        if p.i != p.s.len() {
            return Err(format!(
                "unexpected '{}' at column {} in \"{text}\"",
                p.s[p.i] as char,
                p.i + 1
            ));
        }
        let mut nodes = p.nodes;
        // The root is the last node pushed by construction.
        debug_assert_eq!(root, nodes.len() - 1);
        nodes.shrink_to_fit();
        Ok(Expr { nodes })
    }

    /// A constant expression.
    pub fn constant(x: f64) -> Self {
        Expr {
            nodes: vec![Node::Const(x)],
        }
    }

    pub fn eval(&self, vars: &[f64]) -> f64 {
        self.eval_node(self.nodes.len() - 1, vars)
    }

    fn eval_node(&self, i: usize, v: &[f64]) -> f64 {
        match self.nodes[i] {
            Node::Const(x) => x,
            Node::Var(k) => v[k],
            Node::Neg(a) => -self.eval_node(a, v),
            Node::Add(a, b) => self.eval_node(a, v) + self.eval_node(b, v),
            Node::Sub(a, b) => self.eval_node(a, v) - self.eval_node(b, v),
            Node::Mul(a, b) => self.eval_node(a, v) * self.eval_node(b, v),
            Node::Div(a, b) => self.eval_node(a, v) / self.eval_node(b, v),
        }
    }

    /// Variable slots used (with repetitions).
    pub fn vars(&self) -> impl Iterator<Item = usize> + '_ {
        self.nodes
            .iter()
            .filter_map(|n| if let Node::Var(k) = n { Some(*k) } else { None })
    }
}

struct Parser<'a, 'f> {
    s: &'a [u8],
    i: usize,
    nodes: Vec<Node>,
    slot: &'f mut dyn FnMut(&str) -> Option<usize>,
}

const MAX_DEPTH: usize = 64;

impl Parser<'_, '_> {
    fn ws(&mut self) {
        while self.i < self.s.len() && self.s[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
    }
    fn push(&mut self, n: Node) -> usize {
        self.nodes.push(n);
        self.nodes.len() - 1
    }
    fn peek(&mut self) -> Option<u8> {
        self.ws();
        self.s.get(self.i).copied()
    }
    // expr := term (('+'|'-') term)*
    fn expr(&mut self, depth: usize) -> Result<usize, String> {
        if depth > MAX_DEPTH {
            return Err("expression nested too deeply".into());
        }
        let mut a = self.term(depth)?;
        while let Some(c @ (b'+' | b'-')) = self.peek() {
            self.i += 1;
            let b = self.term(depth)?;
            a = self.push(if c == b'+' {
                Node::Add(a, b)
            } else {
                Node::Sub(a, b)
            });
        }
        Ok(a)
    }
    // term := factor (('*'|'/') factor)*
    fn term(&mut self, depth: usize) -> Result<usize, String> {
        let mut a = self.factor(depth)?;
        while let Some(c @ (b'*' | b'/')) = self.peek() {
            self.i += 1;
            let b = self.factor(depth)?;
            a = self.push(if c == b'*' {
                Node::Mul(a, b)
            } else {
                Node::Div(a, b)
            });
        }
        Ok(a)
    }
    // factor := number | name | '(' expr ')' | '-' factor
    fn factor(&mut self, depth: usize) -> Result<usize, String> {
        if depth > MAX_DEPTH {
            return Err("expression nested too deeply".into());
        }
        match self.peek() {
            None => Err("unexpected end of expression".into()),
            Some(b'(') => {
                self.i += 1;
                let e = self.expr(depth + 1)?;
                if self.peek() != Some(b')') {
                    return Err(format!("missing ')' at column {}", self.i + 1));
                }
                self.i += 1;
                Ok(e)
            }
            Some(b'-') => {
                self.i += 1;
                let a = self.factor(depth + 1)?;
                Ok(self.push(Node::Neg(a)))
            }
            Some(c) if c.is_ascii_digit() || c == b'.' => {
                let st = self.i;
                while self.i < self.s.len()
                    && (self.s[self.i].is_ascii_digit()
                        || self.s[self.i] == b'.'
                        || self.s[self.i] == b'e'
                        || self.s[self.i] == b'E'
                        || ((self.s[self.i] == b'-' || self.s[self.i] == b'+')
                            && matches!(self.s[self.i - 1], b'e' | b'E')))
                {
                    self.i += 1;
                }
                let t = std::str::from_utf8(&self.s[st..self.i]).unwrap_or("");
                let x: f64 = t.parse().map_err(|_| format!("bad number '{t}'"))?;
                Ok(self.push(Node::Const(x)))
            }
            Some(c) if c.is_ascii_alphabetic() || c == b'_' => {
                let st = self.i;
                while self.i < self.s.len()
                    && (self.s[self.i].is_ascii_alphanumeric() || self.s[self.i] == b'_')
                {
                    self.i += 1;
                }
                let name = std::str::from_utf8(&self.s[st..self.i]).unwrap_or("");
                match (self.slot)(name) {
                    Some(k) => Ok(self.push(Node::Var(k))),
                    None => Err(format!("unknown probability name '{name}'")),
                }
            }
            Some(c) => Err(format!(
                "unexpected '{}' at column {}",
                c as char,
                self.i + 1
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(n: &str) -> Option<usize> {
        ["P_sys", "P_obs", "P_V3"].iter().position(|x| *x == n)
    }

    fn ev(t: &str, v: &[f64]) -> f64 {
        Expr::parse(t, &mut names).unwrap().eval(v)
    }

    #[test]
    fn precedence_and_associativity_by_hand() {
        let v = [0.9, 0.5, 0.96];
        assert_eq!(ev("1 - P_sys", &v), 1.0 - 0.9);
        assert_eq!(ev("P_sys * P_obs", &v), 0.45);
        assert_eq!(ev("1 - 0.5 - 0.25", &v), 0.25); // left-associative
        assert_eq!(ev("2 + 3 * 4", &v), 14.0);
        assert_eq!(ev("(2 + 3) * 4", &v), 20.0);
        assert_eq!(ev("10 * P_V3 - 2", &v), 10.0 * 0.96 - 2.0);
        assert_eq!(ev("-P_obs * 2", &v), -1.0);
        assert_eq!(ev("1 - -1", &v), 2.0);
        assert_eq!(ev("8 / 4 / 2", &v), 1.0);
        assert_eq!(ev("1e-1 * 10", &v), 1.0);
        assert_eq!(ev("  0.25 ", &v), 0.25);
    }

    #[test]
    fn rejects_bad_text() {
        for bad in [
            "", "1 -", "(1", "1)", "P_nope", "1 + * 2", "1..2", "2 P_sys", "#",
        ] {
            assert!(Expr::parse(bad, &mut names).is_err(), "{bad:?} accepted");
        }
        let deep = format!("{}1{}", "(".repeat(200), ")".repeat(200));
        assert!(Expr::parse(&deep, &mut names).is_err());
    }
}
