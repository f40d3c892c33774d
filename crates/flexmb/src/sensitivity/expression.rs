//! Criterion expressions: parsing, evaluation and exact gradients.
//!
//! The criteria of a sensitivity analysis are written in the model file as expressions of
//! sensor values and time, e.g. `sq(tip_z - 0.5)`, `(com_x^2 + com_y^2) * 1e3` or
//! `smoothmax(abs(a), 2.0, 0.01)`. [`Expression::parse`] turns the text into an
//! [`Expression`] whose variables are indices into a slice of values; [`Expression::eval`]
//! gives its value and [`Expression::eval_gradient`] its value and its analytic gradient with
//! respect to every variable (one reverse pass over the tree, exact up to rounding).
//!
//! # Grammar
//!
//! ```text
//! expression := term { ("+" | "-") term }
//! term       := unary { ("*" | "/") unary }
//! unary      := ("-" | "+") unary | power
//! power      := primary [ "^" unary ]
//! primary    := number | name | name "(" [ expression { "," expression } ] ")"
//!             | "(" expression ")"
//! number     := digits [ "." [ digits ] ] [ exponent ] | "." digits [ exponent ]
//! exponent   := ("e" | "E") [ "+" | "-" ] digits
//! name       := [A-Za-z_][A-Za-z0-9_]*
//! ```
//!
//! Precedence, from loosest to tightest: `+ -` (left associative), `* /` (left associative),
//! unary `-` and `+`, `^` (right associative). Hence `1 - 2 - 3 = -4`, `8/4/2 = 1`,
//! `2^3^2 = 2^9 = 512`, `-x^2 = -(x^2)` and `2^-1 = 0.5`. Whitespace between tokens is
//! ignored. An expression has at most 10000 characters and at most 64 nested levels
//! (parentheses, function calls, unary signs and exponents).
//!
//! # Names
//!
//! - A name followed by `(` is a function (below); it is never looked up as a variable.
//! - `pi` is the constant 3.14159...
//! - `t` is the time given to `eval`. It is built in: the resolver is not asked about `t`
//!   (a sensor named `t` cannot be used in an expression).
//! - Any other name is passed to the resolver, which returns its variable index.
//!
//! # Functions
//!
//! Partial derivatives are listed in argument order, separated by `;`. In the `smooth*`
//! rows, s = sqrt(x^2 + eps^2) for `smoothabs` and s = sqrt((a-b)^2 + eps^2) otherwise.
//!
//! | Call                   | Value                | Partial derivatives                         |
//! |------------------------|----------------------|---------------------------------------------|
//! | `x ^ y`, `pow(x, y)`   | x^y                  | y x^(y-1); x^y ln(x) (see below)            |
//! | `sq(x)`                | x^2                  | 2x                                          |
//! | `abs(x)`               | abs(x)               | sign(x), 0 at x = 0                         |
//! | `sqrt(x)`              | square root          | 1/(2 sqrt(x))                               |
//! | `exp(x)`               | e^x                  | e^x                                         |
//! | `log(x)`               | natural logarithm    | 1/x                                         |
//! | `sin(x)`               | sine (radians)       | cos(x)                                      |
//! | `cos(x)`               | cosine               | -sin(x)                                     |
//! | `tan(x)`               | tangent              | 1 + tan(x)^2                                |
//! | `min(a, b)`            | smaller argument     | 1; 0 if a <= b, else 0; 1                   |
//! | `max(a, b)`            | larger argument      | 1; 0 if a >= b, else 0; 1                   |
//! | `atan2(y, x)`          | angle of (x, y), rad | x/(x^2 + y^2); -y/(x^2 + y^2)               |
//! | `smoothabs(x, eps)`    | s - eps              | x/s; eps/s - 1                              |
//! | `smoothmax(a, b, eps)` | (a + b + s)/2        | (1 + (a-b)/s)/2; (1 - (a-b)/s)/2; eps/(2s)  |
//! | `smoothmin(a, b, eps)` | (a + b - s)/2        | (1 - (a-b)/s)/2; (1 + (a-b)/s)/2; -eps/(2s) |
//!
//! The operators `a + b`, `a - b`, `a * b`, `a / b` and `-a` have their usual derivatives.
//! `atan2(y, x)` is in [-pi, pi].
//!
//! Calling a function with the wrong number of arguments is an error. `min` and `max` are
//! not differentiable where their arguments are equal: the gradient then goes to the first.
//!
//! Power: when the exponent `y` is a constant expression (no variable and no `t`), the value
//! is `x.powi(y)` if `y` is integer-valued and `x.powf(y)` otherwise, and the derivative is
//! y x^(y-1) (0 if y = 0); ln(x) is not formed, so `x^2` and its gradient are finite at a
//! negative `x`. With a non-constant exponent the value is `x.powf(y)` and d/dy = x^y ln(x)
//! (0 where x^y = 0).
//!
//! Subexpressions without variables and without `t` are folded into constants when parsed.
//! Outside the domain of a function (e.g. `log` of a negative number) the value or the
//! gradient is NaN or infinite, as in IEEE arithmetic.

/// Longest accepted text, in characters.
const MAX_LEN: usize = 10_000;
/// Deepest accepted nesting.
const MAX_DEPTH: usize = 64;

/// A parsed expression; variables are indices into the slice of values given to eval.
#[derive(Clone, Debug, PartialEq)]
pub struct Expression {
    /// The tree in post-order: the arguments of an entry are earlier entries; the root is last.
    ops: Vec<Op>,
}

/// Why a text is not a valid expression, and where. Lexical errors (an unexpected character,
/// an invalid number) are reported before syntax errors; otherwise the first error from the
/// left is reported.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{message} at character {position} of '{text}'")]
pub struct ExpressionError {
    /// The whole text given to [`Expression::parse`].
    pub text: String,
    /// 1-based column, in characters (not bytes), of the offending token: the '(' for an
    /// unclosed parenthesis, one past the last character for an unexpected end.
    pub position: usize,
    /// What is wrong, e.g. "unknown name 'xyz'".
    pub message: String,
}

/// One entry of the tape; indices refer to earlier entries.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Op {
    Num(f64),
    Var(usize),
    Time,
    /// `x ^ c` with a constant exponent `c`.
    PowConst(usize, f64),
    /// `FUNCTIONS[f]` of the entries `args` (the indices past its arity repeat the first).
    Call(usize, [usize; 3]),
}

/// An operator or function: name, number of arguments, value, and partial derivatives given
/// the arguments and the value (the entries past the arity are ignored).
struct Fun {
    name: &'static str,
    arity: usize,
    value: fn([f64; 3]) -> f64,
    partials: fn([f64; 3], f64) -> [f64; 3],
}

const fn fun(
    name: &'static str,
    arity: usize,
    value: fn([f64; 3]) -> f64,
    partials: fn([f64; 3], f64) -> [f64; 3],
) -> Fun {
    Fun {
        name,
        arity,
        value,
        partials,
    }
}

/// Partial derivatives of `x^y` (non-constant exponent).
fn pow_partials([x, y, _]: [f64; 3], v: f64) -> [f64; 3] {
    let dx = if y == 0.0 { 0.0 } else { y * x.powf(y - 1.0) };
    [dx, if v == 0.0 { 0.0 } else { v * x.ln() }, 0.0]
}

/// `smoothmax` (`sign` 1) or `smoothmin` (`sign` -1): (a + b + sign sqrt((a-b)^2 + eps^2))/2.
fn smooth([a, b, eps]: [f64; 3], sign: f64) -> f64 {
    0.5 * (a + b + sign * (a - b).hypot(eps))
}

/// Partial derivatives of [`smooth`].
fn dsmooth([a, b, eps]: [f64; 3], sign: f64) -> [f64; 3] {
    let s = (a - b).hypot(eps);
    let r = sign * (a - b) / s;
    [0.5 * (1.0 + r), 0.5 * (1.0 - r), 0.5 * sign * eps / s]
}

/// The sign of `x`, 0 at 0.
fn sign(x: f64) -> f64 {
    f64::from(u8::from(x > 0.0)) - f64::from(u8::from(x < 0.0))
}

/// Partial derivatives of `min` or `max`: 1 for the first argument if `first`, else for the
/// second.
fn pick(first: bool) -> [f64; 3] {
    let d = f64::from(u8::from(first));
    [d, 1.0 - d, 0.0]
}

const NEG: usize = 0;
const ADD: usize = 1;
const SUB: usize = 2;
const MUL: usize = 3;
const DIV: usize = 4;
/// `pow`, also used for `^`; the entries from here on are the functions callable by name.
const POW: usize = 5;

static FUNCTIONS: [Fun; 20] = [
    fun("neg", 1, |[a, ..]| -a, |_, _| [-1.0; 3]),
    fun("+", 2, |[a, b, _]| a + b, |_, _| [1.0; 3]),
    fun("-", 2, |[a, b, _]| a - b, |_, _| [1.0, -1.0, 0.0]),
    fun("*", 2, |[a, b, _]| a * b, |[a, b, _], _| [b, a, 0.0]),
    fun(
        "/",
        2,
        |[a, b, _]| a / b,
        |[_, b, _], v| [1.0 / b, -v / b, 0.0],
    ),
    fun("pow", 2, |[a, b, _]| a.powf(b), pow_partials),
    fun("sq", 1, |[a, ..]| a * a, |[a, ..], _| [2.0 * a; 3]),
    fun("abs", 1, |[a, ..]| a.abs(), |[a, ..], _| [sign(a); 3]),
    fun("sqrt", 1, |[a, ..]| a.sqrt(), |_, v| [0.5 / v; 3]),
    fun("exp", 1, |[a, ..]| a.exp(), |_, v| [v; 3]),
    fun("log", 1, |[a, ..]| a.ln(), |[a, ..], _| [1.0 / a; 3]),
    fun("sin", 1, |[a, ..]| a.sin(), |[a, ..], _| [a.cos(); 3]),
    fun("cos", 1, |[a, ..]| a.cos(), |[a, ..], _| [-a.sin(); 3]),
    fun("tan", 1, |[a, ..]| a.tan(), |_, v| [1.0 + v * v; 3]),
    fun("min", 2, |[a, b, _]| a.min(b), |[a, b, _], _| pick(a <= b)),
    fun("max", 2, |[a, b, _]| a.max(b), |[a, b, _], _| pick(a >= b)),
    fun(
        "atan2",
        2,
        |[y, x, _]| y.atan2(x),
        |[y, x, _], _| [x / (x * x + y * y), -y / (x * x + y * y), 0.0],
    ),
    fun(
        "smoothabs",
        2,
        |[x, e, _]| x.hypot(e) - e,
        |[x, e, _], _| [x / x.hypot(e), e / x.hypot(e) - 1.0, 0.0],
    ),
    fun("smoothmax", 3, |x| smooth(x, 1.0), |x, _| dsmooth(x, 1.0)),
    fun("smoothmin", 3, |x| smooth(x, -1.0), |x, _| dsmooth(x, -1.0)),
];

/// `x^c`, with `powi` for an integer-valued `c`.
fn powc(x: f64, c: f64) -> f64 {
    if c.fract() == 0.0 && c.abs() <= f64::from(i32::MAX) {
        x.powi(c as i32)
    } else {
        x.powf(c)
    }
}

impl Op {
    /// Indices of the arguments.
    fn args(&self) -> &[usize] {
        match self {
            Op::Num(_) | Op::Var(_) | Op::Time => &[],
            Op::PowConst(a, _) => std::slice::from_ref(a),
            Op::Call(f, args) => &args[..FUNCTIONS[*f].arity],
        }
    }

    /// Value, given the values `v(i)` of the earlier entries.
    fn value(&self, v: impl Fn(usize) -> f64, values: &[f64], t: f64) -> f64 {
        match *self {
            Op::Num(c) => c,
            Op::Var(k) => values[k],
            Op::Time => t,
            Op::PowConst(a, c) => powc(v(a), c),
            Op::Call(f, args) => (FUNCTIONS[f].value)(args.map(v)),
        }
    }
}

impl Expression {
    /// Parses `text`; `resolve(name)` returns Some(index) for a known variable name, None otherwise
    /// (then the error lists the message "unknown name 'xyz'"; the caller adds the list of names).
    ///
    /// `resolve` is not called for `t` (always the time), `pi` (a constant) and function
    /// names. Never panics; the grammar is in the module documentation.
    pub fn parse(
        text: &str,
        resolve: &dyn Fn(&str) -> Option<usize>,
    ) -> Result<Expression, ExpressionError> {
        let chars: Vec<char> = text.chars().collect();
        let (tokens, ops) = (Vec::new(), Vec::new());
        let mut p = Parser {
            text,
            tokens,
            next: 0,
            depth: 0,
            ops,
            resolve,
        };
        if chars.len() > MAX_LEN {
            let message = format!("expression longer than {MAX_LEN} characters");
            return Err(p.error(MAX_LEN + 1, message));
        }
        p.tokens = p.lex(&chars)?;
        if p.tokens.len() == 1 {
            return Err(p.error(1, "empty expression"));
        }
        p.binary(0)?;
        let token = p.peek();
        match token.tok {
            Tok::End => Ok(Expression { ops: p.ops }),
            Tok::Sym(')') => Err(p.error(token.pos, "unbalanced parentheses: ')' without '('")),
            _ => Err(p.error(token.pos, format!("trailing input '{}'", token.text))),
        }
    }

    /// Indices of the variables used, sorted, without repeats.
    pub fn variables(&self) -> Vec<usize> {
        let var = |op: &Op| if let Op::Var(k) = op { Some(*k) } else { None };
        let mut vars: Vec<usize> = self.ops.iter().filter_map(var).collect();
        vars.sort_unstable();
        vars.dedup();
        vars
    }

    /// Value at `values` (indexed by variable index) and time `t`.
    ///
    /// # Panics
    /// If `values` is shorter than one plus the largest index of [`Expression::variables`].
    pub fn eval(&self, values: &[f64], t: f64) -> f64 {
        self.forward(values, t).last().copied().unwrap_or(f64::NAN)
    }

    /// Value and gradient: adds `d(expr)/d(values[i]) * scale` into `grad[i]` for every
    /// variable `i` (`grad` has the same length as `values`), returns the value.
    ///
    /// The derivatives are analytic, computed in reverse mode: one forward pass over the tree
    /// for the values, one backward pass for the adjoints. A branch whose adjoint is exactly
    /// zero (e.g. the unused argument of `min`) contributes nothing, even where its own
    /// derivative is infinite or NaN. The time `t` has no gradient.
    ///
    /// # Panics
    /// If `values` or `grad` is shorter than one plus the largest index of
    /// [`Expression::variables`].
    pub fn eval_gradient(&self, values: &[f64], t: f64, scale: f64, grad: &mut [f64]) -> f64 {
        let v = self.forward(values, t);
        let mut adj = vec![0.0; v.len()];
        if let Some(root) = adj.last_mut() {
            *root = scale;
        }
        for (i, op) in self.ops.iter().enumerate().rev() {
            match (adj[i], *op) {
                (0.0, _) | (_, Op::Num(_) | Op::Time | Op::PowConst(_, 0.0)) => {}
                (g, Op::Var(k)) => grad[k] += g,
                (g, Op::PowConst(a, c)) => adj[a] += g * c * powc(v[a], c - 1.0),
                (g, Op::Call(f, args)) => {
                    let d = (FUNCTIONS[f].partials)(args.map(|k| v[k]), v[i]);
                    for (&k, d) in args.iter().zip(d).take(FUNCTIONS[f].arity) {
                        adj[k] += g * d;
                    }
                }
            }
        }
        v.last().copied().unwrap_or(f64::NAN)
    }

    /// Values of all entries of the tape.
    fn forward(&self, values: &[f64], t: f64) -> Vec<f64> {
        let mut v: Vec<f64> = Vec::with_capacity(self.ops.len());
        for op in &self.ops {
            let x = op.value(|i| v[i], values, t);
            v.push(x);
        }
        v
    }
}

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Num(f64),
    Name(String),
    Sym(char),
    End,
}

#[derive(Clone, Debug)]
struct Token {
    tok: Tok,
    /// 1-based character column.
    pos: usize,
    text: String,
}

/// Recursive-descent parser emitting the tape in post-order.
struct Parser<'a> {
    text: &'a str,
    tokens: Vec<Token>,
    next: usize,
    depth: usize,
    ops: Vec<Op>,
    resolve: &'a dyn Fn(&str) -> Option<usize>,
}

type Parsed = Result<usize, ExpressionError>;

impl Parser<'_> {
    fn error(&self, position: usize, message: impl Into<String>) -> ExpressionError {
        let (text, message) = (self.text.to_string(), message.into());
        ExpressionError {
            text,
            position,
            message,
        }
    }

    /// Splits `chars` into tokens, the last one `End`; the first invalid one is an error.
    fn lex(&self, chars: &[char]) -> Result<Vec<Token>, ExpressionError> {
        let n = chars.len();
        let is = |i: usize, f: fn(&char) -> bool| i < n && f(&chars[i]);
        let skip = |mut i: usize, f: fn(&char) -> bool| {
            while is(i, f) {
                i += 1;
            }
            i
        };
        let (mut tokens, mut i) = (Vec::new(), 0);
        while i < n {
            let (c, start) = (chars[i], i);
            i += 1;
            let tok = if c.is_whitespace() {
                continue;
            } else if c.is_ascii_digit() || c == '.' {
                i = skip(i, |c| c.is_ascii_digit() || *c == '.');
                if is(i, |c| matches!(c, 'e' | 'E')) {
                    let sign = is(i + 1, |c| matches!(c, '+' | '-'));
                    i = skip(i + 1 + usize::from(sign), char::is_ascii_digit);
                }
                let s: String = chars[start..i].iter().collect();
                let number = s.parse().map_err(|_| format!("invalid number '{s}'"));
                Tok::Num(number.map_err(|m| self.error(start + 1, m))?)
            } else if c.is_ascii_alphabetic() || c == '_' {
                i = skip(i, |c| c.is_ascii_alphanumeric() || *c == '_');
                Tok::Name(chars[start..i].iter().collect())
            } else if "+-*/^(),".contains(c) {
                Tok::Sym(c)
            } else {
                return Err(self.error(start + 1, format!("unexpected character '{c}'")));
            };
            let text = chars[start..i].iter().collect();
            tokens.push(Token {
                tok,
                pos: start + 1,
                text,
            });
        }
        let (tok, pos, text) = (Tok::End, n + 1, String::new());
        tokens.push(Token { tok, pos, text });
        Ok(tokens)
    }

    /// The next token (`End` at the end; `lex` never returns an empty list).
    fn peek(&self) -> Token {
        self.tokens[self.next.min(self.tokens.len() - 1)].clone()
    }

    fn advance(&mut self) {
        self.next += 1;
    }

    /// Appends `op`, folded into a constant if all its arguments are constants; returns its
    /// index.
    fn emit(&mut self, mut op: Op) -> usize {
        if let Op::Call(POW, [a, b, _]) = op {
            if let Some(&Op::Num(c)) = self.ops.get(b) {
                op = Op::PowConst(a, c);
                if b + 1 == self.ops.len() {
                    self.ops.pop(); // only used by this power
                }
            }
        }
        // Constant arguments are single entries, so they are the last ones of the tape.
        let first = op.args().iter().copied().min().unwrap_or(usize::MAX);
        let rest = self.ops.get(first..).unwrap_or(&[]);
        if !rest.is_empty() && rest.iter().all(|op| matches!(op, Op::Num(_))) {
            let value = |i: usize| match rest.get(i.wrapping_sub(first)) {
                Some(Op::Num(c)) => *c,
                _ => f64::NAN,
            };
            op = Op::Num(op.value(value, &[], 0.0));
            self.ops.truncate(first);
        }
        self.ops.push(op);
        self.ops.len() - 1
    }

    /// `level` 0: a sum of terms; 1: a product of unary expressions.
    fn binary(&mut self, level: u8) -> Parsed {
        let operand = |p: &mut Self| if level == 0 { p.binary(1) } else { p.unary() };
        let mut lhs = operand(self)?;
        loop {
            let f = match (level, self.peek().tok) {
                (0, Tok::Sym('+')) => ADD,
                (0, Tok::Sym('-')) => SUB,
                (1, Tok::Sym('*')) => MUL,
                (1, Tok::Sym('/')) => DIV,
                _ => return Ok(lhs),
            };
            self.advance();
            let rhs = operand(self)?;
            lhs = self.emit(Op::Call(f, [lhs, rhs, lhs]));
        }
    }

    /// Every recursion passes through here, so the nesting depth (0 at the top level) is
    /// counted here.
    fn unary(&mut self) -> Parsed {
        let token = self.peek();
        if self.depth > MAX_DEPTH {
            return Err(self.error(token.pos, "expression nested too deeply"));
        }
        self.depth += 1;
        let result = match token.tok {
            Tok::Sym('-') => {
                self.advance();
                self.unary().map(|a| self.emit(Op::Call(NEG, [a; 3])))
            }
            Tok::Sym('+') => {
                self.advance();
                self.unary()
            }
            _ => self.power(),
        };
        self.depth -= 1;
        result
    }

    fn power(&mut self) -> Parsed {
        let base = self.primary()?;
        if self.peek().tok != Tok::Sym('^') {
            return Ok(base);
        }
        self.advance();
        let exponent = self.unary()?;
        Ok(self.emit(Op::Call(POW, [base, exponent, base])))
    }

    fn primary(&mut self) -> Parsed {
        let token = self.peek();
        self.advance();
        let op = match token.tok {
            Tok::Num(x) => Op::Num(x),
            Tok::Sym('(') => {
                let args = self.arguments(token.pos, false)?;
                return Ok(args[0]);
            }
            Tok::Name(name) if self.peek().tok == Tok::Sym('(') => {
                return self.call(&name, token.pos);
            }
            Tok::Name(name) => match name.as_str() {
                "pi" => Op::Num(std::f64::consts::PI),
                "t" => Op::Time,
                _ => match (self.resolve)(&name) {
                    Some(k) => Op::Var(k),
                    None => return Err(self.error(token.pos, format!("unknown name '{name}'"))),
                },
            },
            Tok::End => return Err(self.error(token.pos, "unexpected end of expression")),
            Tok::Sym(_) => {
                let m = format!("expected a number, a name or '(', found '{}'", token.text);
                return Err(self.error(token.pos, m));
            }
        };
        Ok(self.emit(op))
    }

    /// The expressions up to the ')' closing the '(' at column `open` (already consumed): one
    /// expression, or if `list` none or several separated by ','.
    fn arguments(&mut self, open: usize, list: bool) -> Result<Vec<usize>, ExpressionError> {
        let mut args = Vec::new();
        if list && self.peek().tok == Tok::Sym(')') {
            self.advance();
            return Ok(args);
        }
        loop {
            args.push(self.binary(0)?);
            let token = self.peek();
            self.advance();
            match token.tok {
                Tok::Sym(')') => return Ok(args),
                Tok::Sym(',') if list => {}
                Tok::End => {
                    return Err(self.error(open, "unbalanced parentheses: '(' is never closed"));
                }
                _ => {
                    let expected = if list { "',' or ')'" } else { "')'" };
                    let m = format!("expected {expected}, found '{}'", token.text);
                    return Err(self.error(token.pos, m));
                }
            }
        }
    }

    /// A call of the function `name` (at column `pos`); the next token is '('.
    fn call(&mut self, name: &str, pos: usize) -> Parsed {
        let Some(f) = (POW..FUNCTIONS.len()).find(|&f| FUNCTIONS[f].name == name) else {
            return Err(self.error(pos, format!("unknown function '{name}'")));
        };
        let open = self.peek().pos;
        self.advance();
        let args = self.arguments(open, true)?;
        let n = FUNCTIONS[f].arity;
        if args.len() != n {
            let (s, found) = (if n == 1 { "" } else { "s" }, args.len());
            let m = format!("function '{name}' takes {n} argument{s}, found {found}");
            return Err(self.error(pos, m));
        }
        let mut ix = [args[0]; 3];
        ix[..n].copy_from_slice(&args);
        Ok(self.emit(Op::Call(f, ix)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(name: &str) -> Option<usize> {
        match name {
            "x" => Some(0),
            "y" => Some(1),
            "z" => Some(2),
            "t" => Some(7), // ignored: `t` is the time
            _ => None,
        }
    }

    fn parse(text: &str) -> Expression {
        Expression::parse(text, &names).unwrap_or_else(|e| panic!("{e}"))
    }

    fn error(text: &str) -> (usize, String) {
        match Expression::parse(text, &names) {
            Ok(e) => panic!("'{text}' parsed as {e:?}"),
            Err(e) => (e.position, e.message),
        }
    }

    /// The gradient at `x` (time 1.5), after checking that the value equals `eval`'s.
    fn gradient(text: &str, x: [f64; 3]) -> [f64; 3] {
        let (e, mut g) = (parse(text), [0.0; 3]);
        let v = e.eval_gradient(&x, 1.5, 1.0, &mut g);
        assert_eq!(v.to_bits(), e.eval(&x, 1.5).to_bits(), "{text}");
        g
    }

    /// Checks the ';'-separated "lhs = rhs" cases at `x` (the right side is parsed too).
    fn check_values(cases: &str, x: [f64; 3], tol: f64) {
        for case in cases.split(';') {
            let (lhs, rhs) = case.split_once('=').unwrap_or((case, "nan"));
            let (l, r) = (parse(lhs).eval(&x, 1.5), parse(rhs).eval(&x, 1.5));
            assert!((l - r).abs() <= tol, "{case}: {l} != {r}");
        }
    }

    /// Compares the gradients of the ';'-separated expressions with the fourth-order central
    /// difference (8 (f(x + h) - f(x - h)) - (f(x + 2h) - f(x - 2h))) / 12h at each point.
    fn check_gradients(texts: &str, points: &[[f64; 3]]) {
        for (text, x) in texts
            .split(';')
            .flat_map(|t| points.iter().map(move |x| (t, x)))
        {
            let (e, g) = (parse(text), gradient(text, *x));
            for i in 0..3 {
                let h = 1e-4 * x[i].abs().max(1.0);
                let f = |d: f64| {
                    let mut y = *x;
                    y[i] += d;
                    e.eval(&y, 1.5)
                };
                let fd = (8.0 * (f(h) - f(-h)) - (f(2.0 * h) - f(-2.0 * h))) / (12.0 * h);
                let tol = 1e-7 * g[i].abs().max(fd.abs()).max(1e-3);
                assert!(
                    (g[i] - fd).abs() <= tol,
                    "{text} at {x:?}: d{i} {} vs {fd}",
                    g[i]
                );
            }
        }
    }

    const POSITIVE: [[f64; 3]; 3] = [[0.7, 1.3, 0.4], [1.9, 0.6, 2.2], [0.35, 2.1, 1.1]];
    const MIXED: [[f64; 3]; 3] = [[-0.8, 0.5, -1.7], [1.2, -2.4, 0.9], [-1.1, -0.3, 0.6]];

    #[test]
    fn precedence_and_associativity() {
        let cases = "2^3^2 = 512; -2^2 = -4; 1 - 2 - 3 = -4; 8/4/2 = 1; 2 + 3 * 4 = 14; \
            (2 + 3) * 4 = 20; 2^-1 = 0.5; -(-3) = 3; +-+2 = -2; 2 * -3 = -6; (-2)^2 = 4; \
            1e-3 * 1000 = 1; .5 + 3. = 3.5; 2.5E+2 = 250; 1E2 = 100; t * 2 = 3; -x^2 = -0.25; \
            x - y^2 / z = -0.5; y^z^0.5 = 4; x^-1 = 2; x * y ^ 2 ^ -1 * z = 2.8284271247461903; \
            2 - -x - +y = 0.5; pi = 3.141592653589793; 2*(3 + 4*(1 - x)) = 10";
        check_values(cases, [0.5, 2.0, 4.0], 0.0);
    }

    #[test]
    fn function_values() {
        let cases = "sq(x) = 9; abs(x) = 3; abs(y) = 3; sqrt(16) = 4; exp(0) = 1; exp(1) = \
            2.718281828459045; log(exp(2)) = 2; sin(pi / 2) = 1; cos(0) = 1; tan(pi / 4) = 1; \
            pow(2, 10) = 1024; pow(x, y) = -27; x ^ y = -27; min(x, 1 - x) = -3; \
            max(x, 1 - x) = 4; atan2(1, 1) = pi / 4; atan2(1, -1) = 3 * pi / 4; \
            smoothabs(x, 4) = 1; smoothabs(x, 0) = 3; smoothmax(1, 4, 4) = 5; \
            smoothmin(1, 4, 4) = 0; smoothmax(x, y, 0) = 3; smoothmin(x, y, 0) = -3";
        check_values(cases, [-3.0, 3.0, 0.0], 1e-15);
    }

    #[test]
    fn gradients_of_functions() {
        let everywhere = "x + y; x - y; x * y; x / y; -x; +x; sq(x); abs(x); exp(x); sin(x); \
            cos(x); tan(x); x^2; x^3; -x^3; x^-2; pow(x, 3); 2^x; x^0; min(x, y); max(x, y); \
            atan2(y, x); smoothabs(x, y); smoothmax(x, y, z); smoothmin(x, y, z)";
        check_gradients(everywhere, &POSITIVE);
        check_gradients(everywhere, &MIXED);
        let positive = "sqrt(x); log(x); x^y; pow(x, y); x^0.5; y^(x / 2); z^y^x";
        check_gradients(positive, &POSITIVE);
    }

    #[test]
    fn gradients_of_composites() {
        let texts = "sq(x - 0.5); (x^2 + y^2) * 1e3; smoothmax(abs(x), 2.0, 0.01); pow(x, 3) - y; \
            exp(sin(x) * cos(y)) / (1 + sq(z)); log(sq(x) + sq(y)) - atan2(z, x) * t; \
            max(x, y) * min(y, z) + smoothabs(x - y, 0.1); -(x - y)^2 / +z + x * x * x; \
            smoothmin(sq(x), y * z, 0.3)^2 + 2^-x + sqrt(sq(y) + 1); x * y * z / (1 + t * x)";
        check_gradients(texts, &POSITIVE);
        check_gradients(texts, &MIXED);
    }

    #[test]
    fn exact_gradients() {
        for x in [-2.5, -1.0, 0.0, 0.3, 7.0] {
            assert_eq!(gradient("sq(x)", [x, 0.0, 0.0]), [2.0 * x, 0.0, 0.0]);
            assert_eq!(gradient("x^2", [x, 0.0, 0.0]), [2.0 * x, 0.0, 0.0]);
            assert_eq!(gradient("x * y + z", [x, 3.0, 1.0]), [3.0, x, 1.0]);
        }
        // A constant exponent: no ln of the negative base.
        let cases = [
            ("x^2", [-2.0, 0.0, 0.0], [-4.0, 0.0, 0.0]),
            ("x^3", [-2.0, 0.0, 0.0], [12.0, 0.0, 0.0]),
            ("x^(1 + 1)", [-2.0, 0.0, 0.0], [-4.0, 0.0, 0.0]),
            ("x^0", [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
            ("y^x", [2.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
            ("abs(x)", [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
            // Ties go to the first argument.
            ("min(x, y)", [1.0, 1.0, 0.0], [1.0, 0.0, 0.0]),
            ("max(x, y)", [1.0, 1.0, 0.0], [1.0, 0.0, 0.0]),
            ("min(x, y)", [2.0, 1.0, 0.0], [0.0, 1.0, 0.0]),
            ("max(x, y)", [1.0, 2.0, 0.0], [0.0, 1.0, 0.0]),
            ("max(x, sqrt(y))", [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
        ];
        for (text, x, expected) in cases {
            assert_eq!(gradient(text, x), expected, "{text}");
        }
        assert_eq!(parse("x^2").eval(&[-2.0], 0.0), 4.0);
        // Scale and accumulation; the time has no gradient.
        let mut g = [1.0; 3];
        let v = parse("x * y + t").eval_gradient(&[2.0, 3.0, 0.0], 0.5, 2.0, &mut g);
        assert_eq!((v, g), (6.5, [7.0, 5.0, 1.0]));
    }

    #[test]
    fn variables_and_folding() {
        assert_eq!(parse("y + x * y + sq(x) - t + pi").variables(), vec![0, 1]);
        assert_eq!(parse("t").eval(&[], 2.5), 2.5);
        assert_eq!(parse("3 * 2").variables(), Vec::<usize>::new());
        assert_eq!(parse("1 + 2 * sq(3)").ops, vec![Op::Num(19.0)]);
        let expected = vec![Op::Var(0), Op::PowConst(0, 2.0)];
        assert_eq!(parse("x^(4 / 2)").ops, expected);
        let resolve = |name: &str| name.strip_prefix('s').and_then(|i| i.parse().ok());
        let e = Expression::parse("s5 * s2 + s5 - s0", &resolve);
        assert_eq!(e.map(|e| e.variables()), Ok(vec![0, 2, 5]));
        let sensors = [
            "tip_z",
            "com_x",
            "com_y",
            "a",
            "heave_acc",
            "x",
            "ref_signal",
        ];
        let resolve = |name: &str| sensors.iter().position(|s| *s == name);
        for (text, vars) in [
            ("sq(tip_z - 0.5)", vec![0]),
            ("(com_x^2 + com_y^2) * 1e3", vec![1, 2]),
            ("smoothmax(abs(a), 2.0, 0.01)", vec![3]),
            ("sq(heave_acc)", vec![4]),
            ("pow(x, 3) - ref_signal", vec![5, 6]),
        ] {
            let e = Expression::parse(text, &resolve).map(|e| e.variables());
            assert_eq!(e, Ok(vars), "{text}");
        }
    }

    #[test]
    fn parse_errors() {
        let cases = [
            ("", 1, "empty expression"),
            ("   ", 1, "empty expression"),
            ("x + $", 5, "unexpected character '$'"),
            ("x + y + \u{3bc}", 9, "unexpected character '\u{3bc}'"),
            ("\u{a0}\u{a0}w", 3, "unknown name 'w'"),
            ("(x + y", 1, "unbalanced parentheses: '(' is never closed"),
            ("2 * sq(x", 7, "unbalanced parentheses: '(' is never closed"),
            ("x + y)", 6, "unbalanced parentheses: ')' without '('"),
            ("(x y)", 4, "expected ')', found 'y'"),
            ("sq(x y)", 6, "expected ',' or ')', found 'y'"),
            ("x y", 3, "trailing input 'y'"),
            ("x, y", 2, "trailing input ','"),
            ("x + w", 5, "unknown name 'w'"),
            ("foo(x)", 1, "unknown function 'foo'"),
            (
                "x + atan2(x)",
                5,
                "function 'atan2' takes 2 arguments, found 1",
            ),
            ("sq()", 1, "function 'sq' takes 1 argument, found 0"),
            ("max(x,y,z)", 1, "function 'max' takes 2 arguments, found 3"),
            (
                "smoothmax(x, y)",
                1,
                "function 'smoothmax' takes 3 arguments, found 2",
            ),
            ("x +", 4, "unexpected end of expression"),
            ("x * * y", 5, "expected a number, a name or '(', found '*'"),
            ("1e + 2", 1, "invalid number '1e'"),
            ("x + .", 5, "invalid number '.'"),
        ];
        for (text, position, message) in cases {
            assert_eq!(error(text), (position, message.to_string()), "{text}");
        }
        let shown = Expression::parse("x + w", &names).map_err(|e| e.to_string());
        assert_eq!(
            shown,
            Err("unknown name 'w' at character 5 of 'x + w'".into())
        );
    }

    #[test]
    fn limits() {
        let nested = |open: &str, n, close: &str| format!("{}x{}", open.repeat(n), close.repeat(n));
        assert_eq!(parse(&nested("(", 64, ")")).eval(&[2.0], 0.0), 2.0);
        assert_eq!(parse(&nested("sq(", 64, ")")).eval(&[1.0], 0.0), 1.0);
        assert_eq!(parse(&nested("-", 64, "")).eval(&[2.0], 0.0), 2.0);
        let deep = [
            nested("(", 65, ")"),
            nested("-", 65, ""),
            nested("sq(", 200, ")"),
        ];
        for text in deep
            .iter()
            .chain([&nested("2^", 65, ""), &nested("(", 4000, ")")])
        {
            assert_eq!(error(text).1, "expression nested too deeply");
        }
        assert_eq!(error(&nested("(", 65, ")")).0, 66);
        let long = format!("{}x", "x+".repeat(5000));
        let too_long = "expression longer than 10000 characters".to_string();
        assert_eq!(error(&long), (10_001, too_long));
        assert_eq!(parse(&long[2..]).eval(&[1.0], 0.0), 5000.0);
    }

    #[test]
    fn random_input_never_panics() {
        let alphabet: Vec<char> = "ab()+-*/^,.1e pisq".chars().collect();
        let resolve = |name: &str| ["a", "b"].iter().position(|n| *n == name);
        let mut state: u64 = 12345;
        let mut next = |m: usize| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as usize % m
        };
        let mut parsed = 0;
        for _ in 0..600 {
            let len = 1 + next(12);
            let text: String = (0..len).map(|_| alphabet[next(alphabet.len())]).collect();
            match Expression::parse(&text, &resolve) {
                Ok(e) => {
                    parsed += 1;
                    assert!(e.variables().iter().all(|&k| k < 2));
                    let mut g = [0.0; 2];
                    let v = e.eval_gradient(&[0.3, -1.2], 0.7, 1.0, &mut g);
                    assert_eq!(v.to_bits(), e.eval(&[0.3, -1.2], 0.7).to_bits());
                }
                Err(e) => assert!((1..=len + 1).contains(&e.position), "{e}"),
            }
        }
        assert!(parsed >= 10, "only {parsed} random strings parsed");
    }
}
