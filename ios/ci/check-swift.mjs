// Checks the Swift of ios/ without a Swift compiler (Linux CI), with tree-sitter-swift:
//  (a) every Swift file under ios/ and the generated bindings parse: no ERROR or MISSING node;
//  (b) every name that the hand-written Swift (the layer in Sources/, the tests, the sample) takes from the
//      bindings exists there: types, initialiser and method argument labels, enum cases (`.bgra8`, also in
//      `case` patterns and against the parameter's enum type), methods and properties used on values whose
//      type is a binding type, and free functions (`packRgba`). The declarations are read from the generated
//      Tensorholo.swift with the same parser, plus what the hand-written layer adds (extensions, new types).
//      Names that are neither declared by the bindings/layer nor anywhere in the checked files must be listed
//      in platform-names.txt (Apple SDK, Swift standard library, XCTest), so a misspelt binding type, free
//      function or enum case fails as well ("closed world");
//  (c) the examples of the READMEs (--readme FILE, repeatable): every ```swift block is extracted; a block of
//      statements is wrapped in a function body (`func readmeExample() throws { … }`, its leading `import`
//      lines kept at file level), parsed (no ERROR/MISSING node) and checked as (b) checks the sample, so a
//      misspelt type, function, method, argument label or enum case fails, reported at the README's line. A
//      block that is a Package.swift fragment (its first code line starts with `.package(`) is wrapped in
//      `Package(name:dependencies: [ … ])` and only parsed (its names are SwiftPM's, as Package.swift's are).
//      A README given without any ```swift block fails (a renamed fence would otherwise check nothing).
//
// Usage: node check-swift.mjs --ios DIR --generated FILE [--platform-names FILE] [--readme FILE]…
// Exit 0 when everything parses and resolves, 1 with file:line messages otherwise.
//
// What it cannot see (needs the compiler on a Mac): types it cannot infer locally (closure parameters,
// generic results, loop variables), overload resolution beyond argument labels, argument types, and the Apple
// APIs themselves (platform-names.txt is a list, not a check of their signatures).
import fs from 'node:fs';
import path from 'node:path';
import Parser from 'tree-sitter';
import Swift from 'tree-sitter-swift';

// ---------------------------------------------------------------------------------------------------------
// Command line
const args = process.argv.slice(2);
function arg(name, fallback) {
  const i = args.indexOf(name);
  if (i >= 0 && i + 1 < args.length) return args[i + 1];
  if (fallback !== undefined) return fallback;
  console.error(`check-swift: missing ${name}`);
  process.exit(2);
}
const iosDir = path.resolve(arg('--ios'));
const generatedFile = path.resolve(arg('--generated'));
const platformFile = path.resolve(arg('--platform-names', path.join(iosDir, 'ci', 'platform-names.txt')));
const readmeFiles = args.flatMap((a, i) => (a === '--readme' && i + 1 < args.length ? [path.resolve(args[i + 1])] : []));

// ---------------------------------------------------------------------------------------------------------
// Parsing
const parser = new Parser();
parser.setLanguage(Swift);

// Constructs valid Swift that tree-sitter-swift 0.7.1 does not parse, blanked (same length, so lines and columns
// stay) before parsing. Each is a grammar gap, not a Swift error; all occur in uniffi's generated code:
//  - an `#if … #endif` block holding only attributes (`#if swift(>=5.8) @_documentation(…) #endif`);
//  - a closure returning the empty tuple, `{ () }`;
//  - the `nonisolated(unsafe)` modifier (its `(unsafe)` part).
const GRAMMAR_GAPS = [
  [/^#if [^\n]*\n(?:[ \t]*@[^\n]*\n)+#endif[ \t]*$/gm, (m) => m.replace(/[^\n]/g, ' ')],
  [/\{ \(\) \}/g, '{    }'],
  [/\bnonisolated\(unsafe\)/g, 'nonisolated        '],
];

function parseText(file, text, extra = {}) {
  for (const [re, sub] of GRAMMAR_GAPS) text = text.replace(re, sub);
  const tree = parser.parse(text, null, { bufferSize: Math.max(text.length * 2, 65536) });
  return { file, text, tree, ...extra };
}
const parseFile = (file) => parseText(file, fs.readFileSync(file, 'utf8'));

/** The ```swift blocks of a Markdown file: { line (README line of the block's first code line), lines }. The
 *  fence's indentation is removed from the block's lines. */
function swiftBlocks(file) {
  const blocks = [];
  let cur = null;
  fs.readFileSync(file, 'utf8').split('\n').forEach((l, i) => {
    if (!cur) {
      const m = /^(\s*)```swift\s*$/.exec(l);
      if (m) cur = { line: i + 2, indent: m[1].length, lines: [] };
    } else if (/^\s*```\s*$/.test(l)) {
      blocks.push(cur);
      cur = null;
    } else cur.lines.push(l.slice(Math.min(cur.indent, l.length - l.trimStart().length)));
  });
  if (cur) blocks.push({ ...cur, unterminated: true });
  return blocks;
}

/** One README block as a parse unit: the Swift text it is checked as, and lineMap (text row → README line,
 *  null for the wrapper's own lines). Lines are not re-indented, so columns are the README's. */
function readmeUnit(file, block) {
  const code = block.lines.map((l, i) => [l, block.line + i]);
  const first = code.find(([l]) => l.trim() && !/^\s*\/\//.test(l));
  const out = [];
  if (first && /^\s*\.package\(/.test(first[0])) {
    out.push(['import PackageDescription', null], ['let package = Package(name: "ReadmeExample", dependencies: [', null]);
    out.push(...code, ['])', null]);
    return parseText(file, out.map(([l]) => l).join('\n') + '\n', { lineMap: out.map(([, n]) => n), readme: 'manifest', block });
  }
  let k = 0;
  while (k < code.length && (/^\s*import\s/.test(code[k][0]) || !code[k][0].trim())) out.push(code[k++]);
  out.push(['func readmeExample() throws {', null], ...code.slice(k), ['}', null]);
  return parseText(file, out.map(([l]) => l).join('\n') + '\n', { lineMap: out.map(([, n]) => n), readme: 'statements', block });
}

function* walk(node) {
  yield node;
  for (let i = 0; i < node.childCount; i++) yield* walk(node.child(i));
}

function where(unit, node) {
  const row = node.startPosition.row;
  if (unit.lineMap) {
    // A README block: the README's line (the nearest block line for the wrapper's own), and which block.
    let line = unit.lineMap[row];
    for (let r = row; line == null && r >= 0; r--) line = unit.lineMap[r];
    line ??= unit.block.line;
    return `${path.relative(process.cwd(), unit.file)}:${line}:${node.startPosition.column + 1} (\`\`\`swift block of line ${unit.block.line - 1})`;
  }
  return `${path.relative(process.cwd(), unit.file)}:${row + 1}:${node.startPosition.column + 1}`;
}

function swiftFiles(dir) {
  const out = [];
  for (const entry of fs.readdirSync(dir, { withFileTypes: true })) {
    const p = path.join(dir, entry.name);
    if (entry.isDirectory()) {
      // Build products and tools; Generated/ is the git-ignored copy of the generated bindings.
      if (['node_modules', '.build', 'build', 'Generated', '.swiftpm'].includes(entry.name) || entry.name.endsWith('.xcodeproj') || entry.name.endsWith('.xcframework')) continue;
      out.push(...swiftFiles(p));
    } else if (entry.name.endsWith('.swift')) {
      out.push(p);
    }
  }
  return out.sort();
}

const errors = [];
const handWritten = swiftFiles(iosDir).filter((f) => path.basename(f) !== 'Package.swift');
const packageSwift = path.join(iosDir, 'Package.swift');
const units = handWritten.map(parseFile);
const generated = parseFile(generatedFile);
const extra = fs.existsSync(packageSwift) ? [parseFile(packageSwift)] : [];
const readmeUnits = [];
for (const file of readmeFiles) {
  const blocks = swiftBlocks(file);
  if (!blocks.length) errors.push(`${path.relative(process.cwd(), file)}: no \`\`\`swift block (a renamed fence would leave its examples unchecked)`);
  for (const b of blocks) {
    if (b.unterminated) errors.push(`${path.relative(process.cwd(), file)}:${b.line - 1}: \`\`\`swift block without its closing fence`);
    else readmeUnits.push(readmeUnit(file, b));
  }
}

for (const unit of [generated, ...units, ...extra, ...readmeUnits]) {
  for (const node of walk(unit.tree.rootNode)) {
    if (node.type === 'ERROR' || node.isMissing) {
      const what = node.isMissing ? `missing ${node.type}` : `syntax error near ${JSON.stringify(unit.text.slice(node.startIndex, node.startIndex + 40))}`;
      errors.push(`${where(unit, node)}: ${what}`);
    }
  }
}
const parsedCount = 1 + units.length + extra.length;
if (errors.length) {
  for (const e of errors) console.error(e);
  console.error(`check-swift: ${errors.length} parse error(s) in ${parsedCount} Swift files and ${readmeUnits.length} README blocks`);
  process.exit(1);
}

// ---------------------------------------------------------------------------------------------------------
// Declarations
const field = (node, name) => node.childForFieldName(name);
const named = (node) => node.namedChildren;
const isPublic = (node) => {
  const mods = node.namedChildren.find((c) => c.type === 'modifiers');
  return !!mods && /\b(public|open)\b/.test(mods.text);
};
const isStatic = (node) => {
  const mods = node.namedChildren.find((c) => c.type === 'modifiers');
  return !!mods && /\b(static|class)\b/.test(mods.text);
};

/** The nominal type a type node names: `Foo` for `Foo`, `Foo?`, `Foo!`, `inout Foo`; `A.B` for nested; null for
 *  tuples, functions, arrays, dictionaries. Generic arguments are dropped (`Result<A, B>` → `Result`). */
function typeName(node) {
  if (!node) return null;
  switch (node.type) {
    case 'user_type':
      return named(node).filter((c) => c.type === 'type_identifier').map((c) => c.text).join('.');
    case 'optional_type':
    case 'implicitly_unwrapped_type':
      return typeName(field(node, 'wrapped') || named(node)[0]);
    case 'type_annotation':
      return typeName(field(node, 'name') || named(node)[0]);
    default:
      return null;
  }
}

const TYPE_NODES = new Set(['user_type', 'optional_type', 'implicitly_unwrapped_type', 'array_type', 'dictionary_type', 'tuple_type', 'function_type', 'opaque_type', 'existential_type', 'metatype', 'protocol_composition_type']);

/** Parameters of a function/init declaration: label (`_` = none), whether it has a default, its type name. */
function parameters(decl) {
  const params = [];
  const kids = [];
  for (let i = 0; i < decl.childCount; i++) kids.push([decl.child(i), decl.fieldNameForChild(i)]);
  for (let k = 0; k < kids.length; k++) {
    const [c] = kids[k];
    if (c.type !== 'parameter') continue;
    const ext = field(c, 'external_name');
    const inner = c.namedChildren.find((n) => n.type === 'simple_identifier' && n !== ext);
    const typeNode = c.namedChildren.find((n) => TYPE_NODES.has(n.type));
    let hasDefault = false;
    for (let j = k + 1; j < kids.length && kids[j][0].type !== 'parameter'; j++) {
      if (kids[j][1] === 'default_value') hasDefault = true;
    }
    const label = ext ? ext.text : inner ? inner.text : '_';
    params.push({ label, hasDefault, type: typeName(typeNode) });
  }
  return params;
}

/** The return type name of a function declaration (the type after `->`). */
function returnType(decl) {
  let arrow = false;
  for (let i = 0; i < decl.childCount; i++) {
    const c = decl.child(i);
    if (c.type === '->') arrow = true;
    else if (arrow && TYPE_NODES.has(c.type)) return typeName(c);
  }
  return null;
}

function declKind(node) {
  for (let i = 0; i < node.childCount; i++) {
    const t = node.child(i).type;
    if (['class', 'struct', 'enum', 'extension', 'actor', 'protocol'].includes(t)) return t;
  }
  return node.type === 'protocol_declaration' ? 'protocol' : 'class';
}

// name → { kind, origin: 'generated' | 'layer' | 'local', checked, members: Map<name, [{kind, type, params, returns, static}]>, inits: [], inherits: [] }
const types = new Map();
// name → [{ params, returns, origin }]
const funcs = new Map();
// Every identifier the hand-written files declare (types, functions, properties, parameters, cases, bindings).
const localNames = new Set();

function typeEntry(name, kind, origin) {
  if (!types.has(name)) types.set(name, { name, kind, origin, checked: origin !== 'local', members: new Map(), inits: [], inherits: [] });
  const t = types.get(name);
  if (kind !== 'extension' && t.kind === 'extension') t.kind = kind;
  return t;
}
function addMember(t, name, entry) {
  if (!t.members.has(name)) t.members.set(name, []);
  t.members.get(name).push(entry);
}

/** Records the declarations of one file. origin: generated (public API only), layer, local (tests, sample). */
function collectDeclarations(unit, origin) {
  const visit = (node, owner) => {
    for (const c of named(node)) {
      switch (c.type) {
        case 'class_declaration':
        case 'protocol_declaration': {
          const kind = declKind(c);
          const nameNode = field(c, 'name');
          const name = kind === 'extension' ? typeName(nameNode) : nameNode?.text;
          if (!name) break;
          if (origin === 'generated' && kind !== 'extension' && !isPublic(c)) break;
          const existing = types.get(name);
          // The layer's extensions of binding types add checked members; an extension in a test or the sample
          // adds members of that file's own, and an extension of a platform type is unchecked.
          if (kind === 'extension' && existing && existing.checked && origin === 'local') break;
          const t = existing ?? typeEntry(name, kind, kind === 'extension' ? 'local' : origin);
          for (const inh of c.namedChildren.filter((n) => n.type === 'inheritance_specifier')) {
            const n = typeName(field(inh, 'inherits_from') || named(inh)[0]);
            if (n) t.inherits.push(n);
          }
          if (origin !== 'generated') localNames.add(name);
          const body = field(c, 'body');
          if (body) visit(body, { type: t, kind, generatedPublicOnly: origin === 'generated' && kind !== 'protocol' && kind !== 'enum' });
          break;
        }
        case 'enum_entry':
          if (owner) {
            for (const n of c.childrenForFieldName('name')) {
              const labels = [];
              const data = field(c, 'data_contents');
              if (data) {
                for (const d of named(data)) if (d.type === 'simple_identifier') labels.push({ label: d.text, hasDefault: false });
              }
              addMember(owner.type, n.text, { kind: 'case', type: owner.type.name, params: labels, static: true });
              if (origin !== 'generated') localNames.add(n.text);
            }
          }
          break;
        case 'function_declaration':
        case 'protocol_function_declaration': {
          const name = field(c, 'name')?.text;
          if (!name) break;
          if (origin === 'generated' && c.type === 'function_declaration' && !isPublic(c)) break;
          const entry = { kind: 'method', params: parameters(c), returns: returnType(c), static: isStatic(c), origin };
          if (owner) addMember(owner.type, name, entry);
          else {
            if (!funcs.has(name)) funcs.set(name, []);
            funcs.get(name).push(entry);
          }
          if (origin !== 'generated') {
            localNames.add(name);
            for (const p of entry.params) localNames.add(p.label);
          }
          break;
        }
        case 'init_declaration':
          if (owner && !(origin === 'generated' && !isPublic(c) && owner.kind !== 'protocol')) owner.type.inits.push({ params: parameters(c), origin });
          break;
        case 'property_declaration':
        case 'protocol_property_declaration': {
          if (origin === 'generated' && owner && owner.generatedPublicOnly && !isPublic(c)) break;
          if (origin === 'generated' && !owner && !isPublic(c)) break;
          const pattern = field(c, 'name');
          const bound = pattern && (field(pattern, 'bound_identifier') || pattern.namedChildren.find((n) => n.type === 'simple_identifier'));
          if (!bound) break;
          const ann = c.namedChildren.find((n) => n.type === 'type_annotation');
          const entry = { kind: 'property', type: typeName(ann), static: isStatic(c), origin };
          if (owner) addMember(owner.type, bound.text, entry);
          if (origin !== 'generated') localNames.add(bound.text);
          break;
        }
        case 'typealias_declaration':
          if (origin !== 'generated') localNames.add(field(c, 'name')?.text ?? '');
          break;
        default:
          break;
      }
    }
  };
  visit(unit.tree.rootNode, null);
  if (origin !== 'generated') {
    // Every other name the file binds: parameters, closure parameters, pattern bindings, generic parameters.
    for (const node of walk(unit.tree.rootNode)) {
      if (node.type === 'parameter') {
        for (const n of node.namedChildren) if (n.type === 'simple_identifier') localNames.add(n.text);
      } else if (node.type === 'lambda_parameter' || node.type === 'type_parameter') {
        for (const n of node.namedChildren) if (n.type === 'simple_identifier' || n.type === 'type_identifier') localNames.add(n.text);
      } else if (node.type === 'pattern' || node.type === 'value_binding_pattern') {
        for (const n of node.namedChildren) if (n.type === 'simple_identifier') localNames.add(n.text);
        const b = field(node, 'bound_identifier');
        if (b) localNames.add(b.text);
      } else if (field(node, 'bound_identifier')) {
        localNames.add(field(node, 'bound_identifier').text);
      }
      for (let i = 0; i < node.childCount; i++) {
        if (node.fieldNameForChild(i) === 'bound_identifier') localNames.add(node.child(i).text);
      }
    }
  }
}

const layerDir = path.join(iosDir, 'Sources', 'Tensorholo');
// Nominal types first, so that an extension (which may come before its type in a file) finds its type; an
// extension of a type that none of these files declares (NSLock, CVPixelBuffer…) is the platform's, unchecked.
for (const [unit, origin] of [[generated, 'generated'], ...units.map((u) => [u, u.file.startsWith(layerDir + path.sep) ? 'layer' : 'local'])]) {
  for (const c of named(unit.tree.rootNode)) {
    if ((c.type === 'class_declaration' || c.type === 'protocol_declaration') && declKind(c) !== 'extension') {
      if (origin === 'generated' && !isPublic(c)) continue;
      const name = field(c, 'name')?.text;
      if (name) typeEntry(name, declKind(c), origin);
    }
  }
}
collectDeclarations(generated, 'generated');
for (const unit of units) if (unit.file.startsWith(layerDir + path.sep)) collectDeclarations(unit, 'layer');
for (const unit of units) if (!unit.file.startsWith(layerDir + path.sep)) collectDeclarations(unit, 'local');
// README examples: what a block declares (its lets, closure parameters) is its own, as in the sample.
const readmeChecked = readmeUnits.filter((u) => u.readme === 'statements');
for (const unit of readmeChecked) collectDeclarations(unit, 'local');

const platformNames = new Set(
  fs.existsSync(platformFile)
    ? fs.readFileSync(platformFile, 'utf8').split('\n').map((l) => l.replace(/#.*/, '').trim()).filter(Boolean)
    : [],
);

// Keywords the grammar reads as names in some positions (`defer { }` as a call with a trailing closure, `Self`).
const SWIFT_KEYWORDS = new Set(['defer', 'Self', 'Any', 'AnyObject', 'some', 'any', 'unchecked', 'main']);

// Members every type has (Swift itself, Equatable/Hashable/Error/CaseIterable conformances the bindings declare).
const UNIVERSAL_MEMBERS = new Set(['self', 'init', 'Type', 'hashValue', 'hash', 'localizedDescription', 'allCases', 'rawValue', 'debugDescription']);

function lookupMember(typeName, name, seen = new Set()) {
  const t = types.get(typeName);
  if (!t || seen.has(typeName)) return null;
  seen.add(typeName);
  if (t.members.has(name)) return t.members.get(name);
  for (const inh of t.inherits) {
    const m = lookupMember(inh, name, seen);
    if (m) return m;
  }
  return null;
}
const isChecked = (typeName) => types.get(typeName)?.checked === true;
const isBindingName = (name) => (types.has(name) && types.get(name).checked) || (funcs.has(name) && funcs.get(name).some((f) => f.origin !== 'local'));

// ---------------------------------------------------------------------------------------------------------
// Uses
const used = new Map(); // "what" → origin ('generated' | 'layer')
let useCount = 0; // every binding use checked (also repeated ones), to report a README block's
function noteUse(what, origin) {
  useCount++;
  if (!used.has(what)) used.set(what, origin);
}
const externalUsed = new Set();

/** Whether `labels` (of a call, `_` = unlabeled) fit `params` in order, skipping defaulted parameters;
 *  parameters left unfilled must have defaults, or be as many as the call's trailing closures. */
function labelsFit(labels, params, trailingClosures) {
  let p = 0;
  for (const label of labels) {
    while (p < params.length && params[p].label !== label && (params[p].hasDefault)) p++;
    if (p >= params.length || params[p].label !== label) return false;
    p++;
  }
  const rest = params.slice(p).filter((q) => !q.hasDefault);
  return rest.length <= trailingClosures;
}
const signature = (params) => `(${params.map((p) => `${p.label}:`).join('')})`;

function callLabels(callExpr) {
  const suffix = callExpr.namedChildren.find((n) => n.type === 'call_suffix');
  const labels = [];
  let trailing = 0;
  if (!suffix) return { labels, trailing, args: [] };
  const args = [];
  for (const c of named(suffix)) {
    if (c.type === 'value_arguments') {
      for (const a of named(c)) {
        if (a.type !== 'value_argument') continue;
        const label = field(a, 'name');
        labels.push(label ? label.text.replace(/:$/, '').trim() : '_');
        args.push(a);
      }
    } else if (c.type === 'lambda_literal') {
      trailing++;
    }
  }
  return { labels, trailing, args };
}

function checkUnit(unit) {
  const env = new Map(); // identifier → type name ('?' when declared twice with different types)
  const bind = (name, type) => {
    if (!name || !type) return;
    if (env.has(name) && env.get(name) !== type) env.set(name, '?');
    else env.set(name, type);
  };
  const fail = (node, message) => errors.push(`${where(unit, node)}: ${message}`);

  const enclosingType = (node) => {
    for (let n = node.parent; n; n = n.parent) {
      if (n.type === 'class_declaration') {
        const kind = declKind(n);
        return kind === 'extension' ? typeName(field(n, 'name')) : field(n, 'name')?.text;
      }
    }
    return null;
  };

  /** The nominal type of an expression when it can be told locally, else null. Static references to a type
   *  come back as `type:Name`. */
  const typeOf = (node) => {
    if (!node) return null;
    switch (node.type) {
      case 'simple_identifier': {
        const t = env.get(node.text);
        if (t && t !== '?') return t;
        if (types.has(node.text)) return `type:${node.text}`;
        return null;
      }
      case 'self_expression':
        return enclosingType(node);
      case 'try_expression':
      case 'await_expression':
        return typeOf(field(node, 'expr') || node.namedChildren[node.namedChildren.length - 1]);
      case 'parenthesized_expression':
      case 'tuple_expression':
        return node.namedChildren.length === 1 ? typeOf(node.namedChildren[0]) : null;
      case 'postfix_expression':
        return typeOf(field(node, 'target'));
      case 'call_expression': {
        const callee = node.namedChildren[0];
        const ct = typeOf(callee);
        if (ct && ct.startsWith('type:')) return ct.slice(5);
        if (callee.type === 'simple_identifier' && funcs.has(callee.text)) return funcs.get(callee.text)[0].returns;
        if (callee.type === 'navigation_expression') {
          const base = typeOf(field(callee, 'target'));
          const member = field(field(callee, 'suffix'), 'suffix')?.text;
          if (base && member) {
            const bt = base.startsWith('type:') ? base.slice(5) : base;
            const m = lookupMember(bt, member);
            if (m) return m[0].kind === 'case' ? bt : m[0].returns ?? null;
          }
        }
        return null;
      }
      case 'navigation_expression': {
        const base = typeOf(field(node, 'target'));
        const member = field(field(node, 'suffix'), 'suffix')?.text;
        if (!base || !member) return null;
        const bt = base.startsWith('type:') ? base.slice(5) : base;
        const m = lookupMember(bt, member);
        if (!m) return null;
        if (m[0].kind === 'case') return bt;
        return m[0].kind === 'property' ? m[0].type : null;
      }
      default:
        return null;
    }
  };

  // Environment first (declarations anywhere in the file, in order): explicit types, then inferred ones.
  for (const node of walk(unit.tree.rootNode)) {
    if (node.type === 'property_declaration') {
      const pattern = field(node, 'name');
      const bound = pattern && (field(pattern, 'bound_identifier') || pattern.namedChildren.find((n) => n.type === 'simple_identifier'));
      const ann = node.namedChildren.find((n) => n.type === 'type_annotation');
      bind(bound?.text, ann ? typeName(ann) : typeOf(field(node, 'value')));
    } else if (node.type === 'parameter' || node.type === 'lambda_parameter') {
      const ids = node.namedChildren.filter((n) => n.type === 'simple_identifier');
      const t = node.namedChildren.find((n) => TYPE_NODES.has(n.type));
      if (ids.length && t) bind(ids[ids.length - 1].text, typeName(t));
    } else if (node.type === 'if_statement' || node.type === 'guard_statement') {
      for (let i = 0; i + 1 < node.childCount; i++) {
        if (node.fieldNameForChild(i) === 'bound_identifier') {
          let j = i + 1;
          while (j < node.childCount && !node.child(j).isNamed) j++;
          if (j < node.childCount) bind(node.child(i).text, typeOf(node.child(j)));
        }
      }
    }
  }

  const checkName = (node, name, what) => {
    if (isBindingName(name)) {
      const t = types.get(name);
      noteUse(`${what} ${name}`, t ? t.origin : funcs.get(name).find((f) => f.origin !== 'local').origin);
      return;
    }
    if (localNames.has(name) || types.has(name) || funcs.has(name)) return;
    if (platformNames.has(name)) {
      externalUsed.add(name);
      return;
    }
    fail(node, `${what} \`${name}\` is declared neither by the bindings (${path.basename(generatedFile)}), the Swift layer, the checked files, nor ${path.basename(platformFile)}`);
  };

  /** Checks `.name` against the cases and static members of enum/type `typeName` (a binding type). */
  const checkImplicitMember = (node, name, expected) => {
    if (expected && isChecked(expected)) {
      const m = lookupMember(expected, name);
      if (!m || !m.some((e) => e.static || e.kind === 'case')) {
        fail(node, `\`.${name}\` is not a case or static member of ${expected}`);
      } else noteUse(`case ${expected}.${name}`, types.get(expected).origin);
      return;
    }
    if (expected) return; // a known non-binding type (Double, CGImagePropertyOrientation…): not checked here
    // Unknown expected type: the name must exist somewhere.
    for (const t of types.values()) {
      if (t.checked && t.members.get(name)?.some((e) => e.static || e.kind === 'case')) {
        noteUse(`case ${t.name}.${name}`, t.origin);
        return;
      }
    }
    if (localNames.has(name)) return;
    if (platformNames.has(`.${name}`)) {
      externalUsed.add(`.${name}`);
      return;
    }
    fail(node, `\`.${name}\` is a case or static member of no binding type, no checked file, nor in ${path.basename(platformFile)}`);
  };

  /** The expected type of the expression `node` when its context tells it: an argument of a call to a binding
   *  init/method/function, the right side of an assignment to a typed property, a `return` in a function with a
   *  declared result type. */
  const expectedType = (node) => {
    const parent = node.parent;
    if (!parent) return null;
    if (parent.type === 'value_argument') {
      const call = parent.parent?.parent?.parent;
      if (!call || call.type !== 'call_expression') return null;
      const { labels, args } = callLabels(call);
      const idx = args.indexOf(args.find((a) => a.id === parent.id));
      const cands = candidates(call);
      if (!cands || idx < 0) return null;
      for (const c of cands) {
        const p = c.params.find((q) => q.label === labels[idx]);
        if (p) return p.type ?? '';
      }
      return null;
    }
    if (parent.type === 'assignment' && field(parent, 'result')?.id === node.id) {
      const target = field(parent, 'target')?.namedChildren[0];
      return target ? typeOf(target) ?? null : null;
    }
    if (parent.type === 'control_transfer_statement' && /^return\b/.test(parent.text)) {
      for (let n = parent.parent; n; n = n.parent) {
        if (n.type === 'function_declaration') return returnType(n);
        if (n.type === 'property_declaration') return typeName(n.namedChildren.find((k) => k.type === 'type_annotation'));
        if (n.type === 'lambda_literal') return null;
      }
    }
    return null;
  };

  /** The declarations a call may resolve to, or null when the callee is not a binding item. */
  const candidates = (call) => {
    const callee = call.namedChildren[0];
    if (callee.type === 'simple_identifier') {
      if (types.has(callee.text) && isChecked(callee.text)) return types.get(callee.text).inits;
      if (funcs.has(callee.text) && isBindingName(callee.text)) return funcs.get(callee.text);
      return null;
    }
    if (callee.type === 'navigation_expression') {
      const base = typeOf(field(callee, 'target'));
      const member = field(field(callee, 'suffix'), 'suffix')?.text;
      if (!base || !member) return null;
      const bt = base.startsWith('type:') ? base.slice(5) : base;
      if (!isChecked(bt)) return null;
      if (member === 'init') return types.get(bt).inits;
      const m = lookupMember(bt, member);
      return m ? m.filter((e) => e.kind === 'method' || e.kind === 'case') : null;
    }
    return null;
  };

  for (const node of walk(unit.tree.rootNode)) {
    switch (node.type) {
      case 'user_type': {
        const first = node.namedChildren.find((n) => n.type === 'type_identifier');
        if (first && !SWIFT_KEYWORDS.has(first.text) && !(node.parent?.type === 'class_declaration' && field(node.parent, 'name')?.id === node.id && declKind(node.parent) !== 'extension')) {
          checkName(first, first.text, 'type');
        }
        break;
      }
      case 'call_expression': {
        const callee = node.namedChildren[0];
        if (callee.type === 'simple_identifier' && !SWIFT_KEYWORDS.has(callee.text)) {
          checkName(callee, callee.text, /^[A-Z]/.test(callee.text) && !/^[A-Z]{2,}[a-z]/.test(callee.text) ? 'type' : 'function');
        }
        const cands = candidates(node);
        if (cands) {
          const { labels, trailing } = callLabels(node);
          const fits = cands.some((c) => labelsFit(labels, c.params, trailing));
          const calleeText = callee.text.replace(/\s+/g, '');
          if (!fits) {
            const known = cands.map((c) => signature(c.params)).join(', ') || 'none';
            fail(node, `no declaration of \`${calleeText}\` takes the arguments (${labels.map((l) => `${l}:`).join('')}); declared: ${known}`);
          } else {
            const origin = cands.find((c) => labelsFit(labels, c.params, trailing))?.origin ?? 'generated';
            noteUse(`call ${calleeText.replace(/^.*\./, (m) => (callee.type === 'navigation_expression' ? '.' : m))}(${labels.map((l) => `${l}:`).join('')})`, origin);
          }
        }
        break;
      }
      case 'navigation_expression': {
        const target = field(node, 'target');
        const member = field(field(node, 'suffix'), 'suffix');
        if (!target || !member || member.type !== 'simple_identifier') break;
        if (target.type === 'simple_identifier' && /^[A-Z]/.test(target.text) && !env.has(target.text) && !SWIFT_KEYWORDS.has(target.text)) {
          checkName(target, target.text, 'type');
        }
        const base = typeOf(target);
        if (!base) break;
        const bt = base.startsWith('type:') ? base.slice(5) : base;
        if (!isChecked(bt) || UNIVERSAL_MEMBERS.has(member.text)) break;
        const m = lookupMember(bt, member.text);
        if (!m) fail(member, `${bt} has no member \`${member.text}\``);
        else noteUse(`member ${bt}.${member.text}`, m[0].origin ?? types.get(bt).origin);
        break;
      }
      case 'prefix_expression': {
        if (node.child(0)?.type !== '.') break;
        const target = field(node, 'target');
        if (target?.type === 'simple_identifier') checkImplicitMember(target, target.text, expectedType(node));
        break;
      }
      case 'switch_entry': {
        const subject = field(node.parent, 'expr');
        const st = subject ? typeOf(subject) : null;
        for (const sp of node.namedChildren.filter((n) => n.type === 'switch_pattern')) {
          for (const p of walk(sp)) {
            if (p.type !== 'pattern') continue;
            // `.name` and `let .name(…)`: a simple_identifier right after a `.` token.
            for (let i = 1; i < p.childCount; i++) {
              if (p.child(i - 1).type === '.' && p.child(i).type === 'simple_identifier') {
                checkImplicitMember(p.child(i), p.child(i).text, st && !st.startsWith('type:') ? st : null);
              }
            }
          }
        }
        break;
      }
      default:
        break;
    }
  }
}

for (const unit of units) checkUnit(unit);
const readmeReport = [];
for (const unit of readmeChecked) {
  const before = useCount;
  checkUnit(unit);
  readmeReport.push(`${path.relative(process.cwd(), unit.file)}:${unit.block.line - 1} (${unit.block.lines.length} lines, ${useCount - before} binding uses)`);
  if (useCount === before) errors.push(`${where(unit, unit.tree.rootNode)}: the block uses no binding name: nothing of it is checked`);
}

if (errors.length) {
  for (const e of errors) console.error(e);
  console.error(`check-swift: ${errors.length} name(s) not declared`);
  process.exit(1);
}
const fromGenerated = [...used.values()].filter((o) => o === 'generated').length;
const fromLayer = used.size - fromGenerated;
console.log(
  `${parsedCount} Swift files parse (${units.length} hand-written, the generated ${path.basename(generatedFile)}${extra.length ? ', Package.swift' : ''}); ` +
    `${used.size} binding names used (${fromGenerated} from the generated bindings, ${fromLayer} from the Swift layer), all declared; ` +
    `${externalUsed.size} platform names from ${path.basename(platformFile)}`,
);
if (readmeFiles.length) {
  const manifests = readmeUnits.filter((u) => u.readme === 'manifest').map((u) => `${path.relative(process.cwd(), u.file)}:${u.block.line - 1}`);
  console.log(
    `${readmeUnits.length} README \`\`\`swift blocks parse; binding names checked in ${readmeChecked.length}: ${readmeReport.join(', ')}` +
      (manifests.length ? `; parsed only (Package.swift fragments): ${manifests.join(', ')}` : ''),
  );
}
if (process.env.CHECK_SWIFT_VERBOSE) {
  for (const [k, o] of [...used.entries()].sort()) console.log(`  ${o}\t${k}`);
}
