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
        if text.len() > MAX_CHARS {
            return Err(format!(
                "expression of {} characters: at most {MAX_CHARS}",
                text.len()
            ));
        }
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
        if nodes.len() > MAX_NODES {
            return Err(format!(
                "expression of {} terms and operations: at most {MAX_NODES}",
                nodes.len()
            ));
        }
        if let Some(x) = nodes.iter().find_map(|n| match n {
            Node::Const(x) if !x.is_finite() => Some(*x),
            _ => None,
        }) {
            return Err(format!(
                "a constant is {x}, not a finite number, in \"{text}\""
            ));
        }
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

    /// Value at `vars`. Children always precede their parent in `nodes` (the parser pushes
    /// them first) and the root is last, so one forward pass over the arena evaluates the tree
    /// without recursion; this is the hot path of filling an MDP in every decision cycle.
    pub fn eval(&self, vars: &[f64]) -> f64 {
        // Most expressions are a constant, a name or `1 - P_x`: the scratch array is sized to
        // the arena (zeroing a 32-slot array for a 1-node expression cost more than evaluating).
        match self.nodes.len() {
            1 => self.forward::<1>(vars),
            2..=4 => self.forward::<4>(vars),
            5..=8 => self.forward::<8>(vars),
            9..=32 => self.forward::<32>(vars),
            n => self.eval_node(n - 1, vars),
        }
    }

    #[inline(always)]
    fn forward<const N: usize>(&self, vars: &[f64]) -> f64 {
        let mut val = [0.0f64; N];
        let n = self.nodes.len();
        for (i, node) in self.nodes.iter().enumerate() {
            val[i] = match *node {
                Node::Const(x) => x,
                Node::Var(k) => vars[k],
                Node::Neg(a) => -val[a],
                Node::Add(a, b) => val[a] + val[b],
                Node::Sub(a, b) => val[a] - val[b],
                Node::Mul(a, b) => val[a] * val[b],
                Node::Div(a, b) => val[a] / val[b],
            };
        }
        val[n - 1]
    }

    /// The same value by recursion from the root (the path for arenas over 32 nodes, and the
    /// reference the forward pass is tested against).
    pub fn eval_recursive(&self, vars: &[f64]) -> f64 {
        self.eval_node(self.nodes.len() - 1, vars)
    }

    /// Number of nodes in the arena (after constant folding).
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Never true: an expression has at least one node.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
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
/// Longest expression text (bytes). The shipped MDPs use under 60; the limit keeps parsing and
/// the recursive evaluation of large arenas far from any stack limit.
pub const MAX_CHARS: usize = 2000;
/// Most nodes (numbers, names, operations) in one compiled expression.
pub const MAX_NODES: usize = 256;

impl Parser<'_, '_> {
    fn ws(&mut self) {
        while self.i < self.s.len() && self.s[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
    }
    /// Push `n`, folding an operation on constants into one constant (an operand that is a
    /// constant is a single node, pushed just before, so it is popped). The folded value is the
    /// same IEEE operation evaluation would do, so results are bit-identical.
    fn push(&mut self, n: Node) -> usize {
        let c = |p: &Self, i: usize| match p.nodes[i] {
            Node::Const(x) => Some(x),
            _ => None,
        };
        let folded = match n {
            Node::Neg(a) => c(self, a).map(|x| (1, -x)),
            Node::Add(a, b) | Node::Sub(a, b) | Node::Mul(a, b) | Node::Div(a, b) => {
                match (c(self, a), c(self, b)) {
                    (Some(x), Some(y)) => Some((
                        2,
                        match n {
                            Node::Add(..) => x + y,
                            Node::Sub(..) => x - y,
                            Node::Mul(..) => x * y,
                            _ => x / y,
                        },
                    )),
                    _ => None,
                }
            }
            _ => None,
        };
        match folded {
            Some((k, x)) => {
                let len = self.nodes.len() - k;
                self.nodes.truncate(len);
                self.nodes.push(Node::Const(x));
            }
            None => self.nodes.push(n),
        }
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

    #[test]
    fn constants_fold_at_parse() {
        let p = |t: &str| Expr::parse(t, &mut names).unwrap();
        assert_eq!(p("1 - 0.5 - 0.25").len(), 1);
        assert_eq!(p("-(2 * 3)").len(), 1);
        // P_sys, the folded 0.95, the product: 3 nodes.
        assert_eq!(p("P_sys * (1 - 0.1 * 0.5)").len(), 3);
        assert_eq!(
            p("P_sys * (1 - 0.1 * 0.5)").eval(&[0.9, 0.0, 0.0]),
            0.9 * 0.95
        );
    }

    /// A random expression tree, evaluated by the test itself (independent of the parser).
    #[derive(Debug, Clone)]
    enum T {
        C(f64),
        V(usize),
        Neg(Box<T>),
        Bin(u8, Box<T>, Box<T>),
    }

    impl T {
        fn text(&self) -> String {
            match self {
                T::C(x) => format!("{x:?}"),
                T::V(k) => ["P_sys", "P_obs", "P_V3"][*k].to_string(),
                T::Neg(a) => format!("-({})", a.text()),
                T::Bin(op, a, b) => format!("({} {} {})", a.text(), *op as char, b.text()),
            }
        }
        fn value(&self, v: &[f64]) -> f64 {
            match self {
                T::C(x) => *x,
                T::V(k) => v[*k],
                T::Neg(a) => -a.value(v),
                T::Bin(op, a, b) => {
                    let (x, y) = (a.value(v), b.value(v));
                    match op {
                        b'+' => x + y,
                        b'-' => x - y,
                        b'*' => x * y,
                        _ => x / y,
                    }
                }
            }
        }
    }

    fn tree() -> impl proptest::strategy::Strategy<Value = T> {
        use proptest::prelude::*;
        let leaf = prop_oneof![(0.0f64..10.0).prop_map(T::C), (0usize..3).prop_map(T::V)];
        leaf.prop_recursive(6, 64, 2, |inner| {
            prop_oneof![
                inner.clone().prop_map(|a| T::Neg(Box::new(a))),
                (
                    prop_oneof![Just(b'+'), Just(b'-'), Just(b'*'), Just(b'/')],
                    inner.clone(),
                    inner
                )
                    .prop_map(|(o, a, b)| T::Bin(o, Box::new(a), Box::new(b))),
            ]
        })
    }

    proptest::proptest! {
        /// Forward-pass and recursive evaluation of the parsed (constant-folded) arena give
        /// bit-for-bit the value of the tree it was printed from, small and large arenas alike.
        #[test]
        fn parsed_expressions_evaluate_like_their_tree(
            t in tree(),
            v in proptest::array::uniform3(0.0f64..1.0),
        ) {
            let e = Expr::parse(&t.text(), &mut names).unwrap();
            let want = t.value(&v);
            proptest::prop_assert_eq!(e.eval(&v).to_bits(), want.to_bits(), "{}", t.text());
            proptest::prop_assert_eq!(e.eval_recursive(&v).to_bits(), want.to_bits());
        }
    }
}
