"""The package's shape (docs/design.md "Layout"): no import cycle, no rclpy under core/, one
node registry that setup, the stack and the tools agree with, one topic table.

Layers of core/, lowest first (a folder imports only folders before it; core/*.py modules --
stats, topics, jit_cache, kernel_records -- are below every folder and import none):
config, plant, io, bridge, hardware, redundancy, controller, qft, estimator, loop, sweep, sim,
ident. bridge is the ADS transport the hardware backend uses; the plant-side nodes' schemas
(hardware/sim_params.py, hardware/bridge_params.py) sit beside the hardware side; controller.lti
(transfer functions) is below the QFT design; the random family's box (qft.family_box) below
the estimator's tuning; loop (safe state, supervisor) composes estimator and redundancy; a sweep's
figures and plots (sweep.analysis, sweep.plots) are below the batch scenarios that use them."""
import ast
import os

import eha_ros
from eha_ros.core.config import registry

BASE = os.path.dirname(os.path.abspath(eha_ros.__file__))


def _modules() -> dict:
    """module name -> file, for every .py of eha_ros."""
    out = {}
    for folder, _, names in os.walk(BASE):
        for name in names:
            if name.endswith('.py'):
                path = os.path.join(folder, name)
                rel = os.path.relpath(path, os.path.dirname(BASE))[:-3].replace(os.sep, '.')
                out[rel[:-len('.__init__')] if rel.endswith('.__init__') else rel] = path
    return out


def _imports(module: str, path: str, modules: dict) -> set:
    """Modules of eha_ros that ``module`` imports anywhere (functions included); a package's
    __init__ counts as the package only when it is named alone."""
    tree = ast.parse(open(path, encoding='utf-8').read())
    package = module if path.endswith('__init__.py') else module.rpartition('.')[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split('.')
                parts = parts[:len(parts) - node.level + 1]
                base = '.'.join(parts + ([node.module] if node.module else []))
            else:
                base = node.module or ''
            targets = [f'{base}.{a.name}' for a in node.names] + [base]
        else:
            continue
        for t in targets:
            while t and t not in modules:
                t = t.rpartition('.')[0]
            if t and t != module and not modules[t].endswith('__init__.py'):
                found.add(t)
    return found


def _cycles(graph: dict) -> list:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))
    return out


def test_cycle_finder_finds_a_cycle():
    graph = {'a': {'b'}, 'b': {'c'}, 'c': {'a'}, 'd': {'a'}, 'e': set()}
    assert _cycles(graph) == [['a', 'b', 'c']]
    assert _cycles({'a': {'b'}, 'b': set()}) == []


def test_no_import_cycle_in_eha_ros():
    modules = _modules()
    graph = {m: _imports(m, p, modules) for m, p in modules.items()}
    assert graph['eha_ros.core.sim.batch'], 'the import graph is empty: the parser is broken'
    cycles = _cycles(graph)
    print(f'{len(modules)} modules, {sum(map(len, graph.values()))} import edges, '
          f'cycles: {cycles}')
    assert cycles == []


def test_core_never_imports_rclpy():
    offenders = []
    for module, path in _modules().items():
        if not module.startswith('eha_ros.core'):
            continue
        for node in ast.walk(ast.parse(open(path, encoding='utf-8').read())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ''] if isinstance(node, ast.ImportFrom) else []
            if any(n == 'rclpy' or n.startswith('rclpy.') for n in names):
                offenders.append(module)
    assert offenders == []


def test_every_registered_node_has_its_executable_module_and_files():
    from eha_ros.core.config.params import default_config_dir
    cfg = default_config_dir()
    for info in registry.NODES.values():
        path = os.path.join(BASE, 'nodes', f'{info.name}.py')
        assert os.path.isfile(path), info.name
        assert 'def main(' in open(path, encoding='utf-8').read(), info.name
        for f in info.files:
            assert os.path.isfile(os.path.join(cfg, f)), (info.name, f)
        if info.schema:
            assert registry.schema_for(info.name).node == info.name
    # the loop that eha_loop composes and the stack starts: plant sides first, then loop nodes,
    # then the tools that answer its ticks (the experiment node)
    from eha_ros import stack
    assert stack.LOOP_NODES == registry.PLANT_NODES + registry.LOOP_NODES + registry.LOOP_TOOLS
    assert registry.LOOP_TOOLS == ('experiment',)
    assert set(registry.LOOP_PREFIX) == set(registry.PLANT_NODES)


def test_installed_executables_are_the_registry():
    """setup.py reads its console scripts from the registry: the venv has each of them."""
    import sys
    bindir = os.path.dirname(sys.executable)
    missing = [n.executable for n in registry.NODES.values()
               if not os.path.exists(os.path.join(bindir, n.executable))]
    assert missing == []


# ------------------------------------------------------------------- folders of core/
def _core_folder_graph(modules: dict) -> dict:
    """core folder (or top-level core module) -> the core folders/modules it imports."""
    graph = {}
    for m, p in modules.items():
        parts = m.split('.')
        if parts[:2] != ['eha_ros', 'core'] or len(parts) < 3:
            continue
        src = parts[2]
        graph.setdefault(src, set())
        for t in _imports(m, p, modules):
            q = t.split('.')
            if q[:2] == ['eha_ros', 'core'] and len(q) > 2 and q[2] != src:
                graph[src].add(q[2])
    return graph


def _folder_cycles(graph: dict) -> list:
    """Import cycles between folders: strongly connected components (pairs included)."""
    return _cycles({k: set(v) & set(graph) for k, v in graph.items()})


def test_folder_cycle_finder_finds_a_planted_cycle():
    modules = _modules()
    graph = _core_folder_graph(modules)
    assert graph['sim'] >= {'plant', 'estimator', 'controller'}, graph['sim']
    planted = {k: set(v) for k, v in graph.items()}
    planted['plant'].add('sim')                       # plant -> sim -> plant
    assert any({'plant', 'sim'} <= set(c) for c in _folder_cycles(planted))
    assert _folder_cycles({'a': {'b'}, 'b': {'a'}, 'c': set()}) == [['a', 'b']]


def test_no_two_core_folders_import_each_other():
    graph = _core_folder_graph(_modules())
    cycles = _folder_cycles(graph)
    print({k: sorted(v) for k, v in sorted(graph.items())})
    assert cycles == []


# --------------------------------------------------------------------- one topic table
def _topic_literals(path: str, names: set) -> list:
    """(line, text) of string constants (not docstrings) that name a topic of ``names``."""
    tree = ast.parse(open(path, encoding='utf-8').read())
    docs = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                docs.add(id(body[0].value))
    return [(n.lineno, n.value) for n in ast.walk(tree)
            if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs
            and n.value.lstrip('/') in names]


def _topic_offenders() -> dict:
    from eha_ros.core import topics
    names = {t.name for t in topics.TOPICS + topics.SERVICES}
    table = os.path.join(BASE, 'core', 'topics.py')
    out = {}
    for path in _modules().values():
        if path != table:
            found = _topic_literals(path, names)
            if found:
                out[os.path.relpath(path, BASE)] = found
    return out


def test_topic_finder_finds_a_planted_literal(tmp_path):
    f = tmp_path / 'x.py'
    f.write_text('"""eha/state in a docstring is fine."""\nA = "/eha/state"\nB = "eha/statex"\n'
                 'def f():\n    """eha/command"""\n    return "eha/command"\n')
    assert _topic_literals(str(f), {'eha/state', 'eha/command'}) == \
        [(2, '/eha/state'), (6, 'eha/command')]


def test_topic_names_come_from_the_table():
    """Only core/topics.py spells a topic's or a service's name (with or without the leading
    slash)."""
    offenders = _topic_offenders()
    assert offenders == {}, f'{len(offenders)} files spell a topic name: {offenders}'
