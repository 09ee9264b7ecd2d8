"""The kernels' decorators: numba's `njit` with the engine's options when this process runs the
compiled kernels (`collide.engine.tier` decides), or nothing, so the same code runs as Python."""

from __future__ import annotations

import functools
import importlib.util
import os
import sys
import threading

from collide.engine import tier

# Imported by numba's own import only to read a .numba_config.yaml (yaml, 0.015 s of CPU) and to
# check that scipy is 1.0 or later (0.008 s; collide's tests ask for 1.10).
NUMBA_OPTIONAL = ("yaml", "scipy")


def _import_numba_without_optional() -> None:
    """Import numba as if NUMBA_OPTIONAL were not installed (None in sys.modules stops an
    import), and leave them importable. Not when the working folder has a .numba_config.yaml,
    the only file numba reads with yaml."""
    if "numba" in sys.modules or os.path.isfile(".numba_config.yaml"):
        return
    blocked = [name for name in NUMBA_OPTIONAL if name not in sys.modules]
    sys.modules.update(dict.fromkeys(blocked))
    try:
        import numba  # noqa: F401
    finally:
        for name in blocked:
            if sys.modules.get(name, 0) is None:
                del sys.modules[name]


@functools.cache
def _skip_blas_probe() -> None:
    """numba's target set-up, which compiling needs, imports scipy.linalg (0.2 s of CPU) only to
    record whether BLAS is there for its matrix products. The kernels use none. Record it from
    whether scipy is installed, as numba's probe would; scipy.linalg is then imported only if
    something compiles a BLAS call."""
    from numba.np import linalg

    probe = linalg.ensure_blas

    def unprobed() -> None:
        raise ImportError("not probed")

    linalg.ensure_blas = unprobed
    try:
        from numba.np import arraymath
    finally:
        linalg.ensure_blas = probe
    arraymath.ensure_blas = probe
    arraymath._HAVE_BLAS = importlib.util.find_spec("scipy") is not None


def _set_up_target_to_compile_only() -> None:
    """numba sets up its whole compiler target (imports and registers every lowering it has, 0.3 s
    of CPU, a third of a compiled run's start) before it looks in its cache, although cached
    machine code needs only numba's runtime. Loading from the cache starts the runtime only; the
    compiler sets the target up by itself when something is compiled (without the BLAS probe)."""
    from numba.core import caching, cpu
    from numba.core.runtime import rtsys

    def load_overload(self, sig, target_context):
        rtsys.initialize(target_context)
        with self._guard_against_spurious_io_errors():
            return self._load_overload(sig, target_context)

    set_up = cpu.CPUContext.load_additional_registries

    def load_additional_registries(self) -> None:
        _skip_blas_probe()
        while _PUT_OFF:  # before numba imports them by name, which would not load them
            _PUT_OFF.pop().__spec__  # noqa: B018 - an attribute loads the module
        set_up(self)

    caching.Cache.load_overload = load_overload
    cpu.CPUContext.load_additional_registries = load_additional_registries


# numba modules that cached kernels' environments name, put off (`_load_environments_lazily`)
# until the compiler target is set up.
_PUT_OFF: list = []
# numba modules that register machine-code symbols when imported (the string hash's secrets):
# imported whenever an environment names them, as the kernels' code may use the symbols.
_IMPORTED_FOR_SYMBOLS = ("numba.cpython.hashing",)


def _load_environments_lazily() -> None:
    """A cached kernel holds an environment (a module's globals, which only object-mode code
    reads) for each function compiled into it, numba's own among them, and numba imports each
    such module to take its globals when it loads the kernel: numba's array, string and maths
    lowerings, 0.05 s of CPU, most of the loading. A numba module not imported yet is put in
    sys.modules to load at its first use (`tier._load_when_used`) and the environment gets its
    globals' dict, which is the module's own once it loads; setting the compiler up loads such
    modules first, so that their lowerings register as they would have."""
    from numba.core import environment

    def _rebuild_env(modname, consts, env_name):
        env = environment.lookup_environment(env_name)
        if env is not None:
            return env
        env = environment.Environment(_globals_of(modname))
        env.consts[:] = consts
        env.env_name = env_name
        environment.Environment._memo[env_name] = env
        return env

    # Pickled by name as numba's own, so that the cache's files stay the same.
    _rebuild_env.__module__, _rebuild_env.__qualname__ = environment.__name__, "_rebuild_env"
    environment._rebuild_env = _rebuild_env


def _globals_of(name: str) -> dict:
    """The globals of module `name`, a numba module not imported yet being put off (`_PUT_OFF`)."""
    module = sys.modules.get(name)
    if module is None and name.startswith("numba.") and name not in _IMPORTED_FOR_SYMBOLS:
        tier._load_when_used(name)
        module = sys.modules.get(name)
        if module is not None:
            _PUT_OFF.append(module)
    if module is None:
        module = importlib.import_module(name)
    return object.__getattribute__(module, "__dict__")  # not `module.__dict__`, which would load it


def _type_arrays_without_numpy_ma() -> None:
    """numba checks that an array it types is no masked array, which imports numpy.ma (0.01 s of
    CPU) at a run's first kernel call. An array of numpy's own type is none: typed as numba
    would, without the check."""
    import numpy as np
    from numba.core import types
    from numba.core.typing.typeof import typeof_impl
    from numba.np import numpy_support

    checked = typeof_impl.dispatch(np.ndarray)

    def typeof_array(val, c):
        if type(val) is not np.ndarray or val.dtype.kind not in "biufc":
            return checked(val, c)
        dtype = numpy_support.from_dtype(val.dtype)
        return types.Array(dtype, val.ndim, numpy_support.map_layout(val), readonly=not val.flags.writeable)

    typeof_impl.register(np.ndarray, typeof_array)


def _parse_bitcode_when_linked() -> None:
    """numba stores a cached kernel as machine code and as LLVM bitcode (for compiling it into a
    kernel that calls it), and parses the bitcode when it loads the kernel, to list its symbols
    (0.09 s of CPU for the event engine, a seventh of a compiled run's start). Only a compile
    that links the loaded kernel into another needs it: parse it then; the entry point's
    address is looked up in the loaded machine code."""
    import llvmlite.binding as ll
    from numba.core import codegen

    library = codegen.JITCodeLibrary
    unserialize = library._unserialize.__func__
    for_linking = library._get_module_for_linking
    pointer_to = library.get_pointer_to_function

    def _unserialize(cls, owner, state):
        name, kind, data = state
        if kind != "object":
            return unserialize(cls, owner, state)
        object_code, bitcode = data
        self = owner.create_library(name)
        self.enable_object_caching()
        self._set_compiled_object(object_code)
        self._finalize_final_module()
        self._unparsed_bitcode = bitcode
        return self

    def _get_module_for_linking(self):
        bitcode = self.__dict__.pop("_unparsed_bitcode", None)
        if bitcode is not None:
            self._shared_module = ll.parse_bitcode(bitcode)
            self._codegen._engine._load_defined_symbols(self._shared_module)
        return for_linking(self)

    def get_pointer_to_function(self, name):
        if "_unparsed_bitcode" not in self.__dict__:
            return pointer_to(self, name)
        self._ensure_finalized()
        return self._codegen._engine.get_function_address(name)

    library._unserialize = classmethod(_unserialize)
    library._get_module_for_linking = _get_module_for_linking
    library.get_pointer_to_function = get_pointer_to_function


def _compile_only_what_runs() -> None:
    """numba optimises every compiled library as a whole and compiles it to machine code as soon
    as it is finished, also the libraries of kernel parts that only other kernels call: their
    code is linked into each caller's library, optimised and compiled again there, and their
    own machine code never runs. A finished library here is optimised as a module and compiled
    when it is to run (numba asks for an entry point that it defines) or is saved to the cache
    with machine code; until then a caller links its code as numba's function passes left it,
    and the caller's module optimisation (the same passes) sees the parts' code once, with its
    own. A part that never runs is cached as bitcode (numba's other cache format)."""
    import llvmlite.binding as ll
    from numba.core import codegen
    from numba.core.compiler_lock import require_global_compiler_lock

    library = codegen.JITCodeLibrary
    pointer_to = library.get_pointer_to_function
    unserialize = library._unserialize.__func__
    as_object_code = library.serialize_using_object_code

    def finalize(self) -> None:
        require_global_compiler_lock()
        self._codegen._check_llvm_bugs()
        self._raise_if_finalized()
        seen = set()
        for linked in self._linking_libraries:
            if linked not in seen:
                self._reload_init.update(linked._reload_init)
                seen.add(linked)
                self._final_module.link_in(linked._get_module_for_linking(), preserve=True)
        self._finalize_dynamic_globals()
        self._verify_declare_only_symbols()
        self._finalized = True
        self._not_compiled = True

    def compile_now(self) -> None:
        if self.__dict__.pop("_not_compiled", False):
            self._optimize_final_module()
            self._final_module.verify()
            self._dynamic_globals.clear()
            self._finalize_final_module()

    def get_pointer_to_function(self, name):
        self._ensure_finalized()
        if "_not_compiled" in self.__dict__:
            if not _defines(self, name):
                return 0
            compile_now(self)
        return pointer_to(self, name)

    def serialize_using_object_code(self):
        self._ensure_finalized()
        if "_not_compiled" in self.__dict__:
            return (self.name, "bitcode", self._final_module.as_bitcode())
        return as_object_code(self)

    def _unserialize(cls, owner, state):
        name, kind, data = state
        if kind != "bitcode":
            return unserialize(cls, owner, state)
        self = owner.create_library(name)
        self.enable_object_caching()  # compiled when it first runs, then cached with machine code
        self._final_module = ll.parse_bitcode(data)
        self._finalize_dynamic_globals()
        self._finalized = True
        self._not_compiled = True
        return self

    def set_env(self, env_name, env) -> None:
        # A part not compiled has no environment to set; its copies in the kernels that call it
        # leave theirs unset, as the kernels loaded from the cache always have.
        if self._engine.get_global_value_address(env_name):
            set_environment(self, env_name, env)

    set_environment = codegen.JITCPUCodegen.set_env
    codegen.JITCPUCodegen.set_env = set_env
    library.finalize = finalize
    library.get_pointer_to_function = get_pointer_to_function
    library.serialize_using_object_code = serialize_using_object_code
    library._unserialize = classmethod(_unserialize)


def _compile_entries_when_called() -> None:
    """numba compiles every kernel with its entry from Python ready to be called, although most
    kernels are only called by other kernels, which hold their code. A kernel here gets an entry
    that compiles its library (`_compile_only_what_runs`) at its first call from Python, and the
    dispatcher uses the compiled entry from then on."""
    from numba.core import cpu, dispatcher
    from numba.core.compiler_lock import global_compiler_lock

    executable = cpu.CPUContext.get_executable
    add = dispatcher.Dispatcher.add_overload

    class Entry:
        def __init__(self, context, library, fndesc, env) -> None:
            self.made = (context, library, fndesc, env)
            self.compiled = None
            self.ready = None

        def __call__(self, *args, **kwargs):
            if self.compiled is None:
                self.make()
            return self.compiled(*args, **kwargs)

        def make(self) -> None:
            with global_compiler_lock:
                if self.compiled is None:
                    compiled = executable(*self.made)
                    if self.ready is not None:
                        self.ready(compiled)
                    self.compiled = compiled

    def get_executable(self, library, fndesc, env):
        compiled = library._finalized and "_not_compiled" not in library.__dict__
        if not compiled and _defines(library, fndesc.llvm_cpython_wrapper_name):
            return Entry(self, library, fndesc, env)
        return executable(self, library, fndesc, env)

    def add_overload(self, cres) -> None:
        entry = cres.entry_point
        if not isinstance(entry, Entry):
            return add(self, cres)
        if entry.compiled is not None:
            return add(self, _callable_as(cres, entry.compiled))
        # Not in the dispatcher's table: a call from Python asks numba's compile, which returns
        # this entry; once compiled it goes into the table.
        args = tuple(cres.signature.args)

        def ready(compiled) -> None:
            done = _callable_as(cres, compiled)
            add(self, done)
            self._cache.save_overload(args, done)  # again, now with its machine code

        entry.ready = ready
        self.overloads[args] = cres

    cpu.CPUContext.get_executable = get_executable
    dispatcher.Dispatcher.add_overload = add_overload


def compile_with_entry(kernel, types: tuple) -> None:
    """Compile (or load) `kernel` for `types` with its entry from Python ready now, not at the
    first call (which a run makes inside its clock)."""
    kernel.compile(types)
    make = getattr(kernel.overloads[tuple(types)].entry_point, "make", None)
    if make is not None:
        make()


def _callable_as(cres, compiled):
    """`cres` with its compiled entry in place of the Entry. numba finds the code of a call from
    a kernel under the callee's entry point (the dispatcher's `overloads[args].entry_point`) in
    its table of user functions, where the compile or cache load put it under the Entry: the
    compiled entry is registered there too, or any kernel compiled later in the process that
    calls this one fails with "No definition for lowering"."""
    if not cres.objectmode:
        cres.target_context.insert_user_function(compiled, cres.fndesc, [cres.library])
    return cres._replace(entry_point=compiled)


def _defines(library, name: str) -> bool:
    try:
        return not library._final_module.get_function(name).is_declaration
    except NameError:
        return False


# How LLVM optimises the kernels (numba's NUMBA_OPT, NUMBA_LOOP_VECTORIZE, NUMBA_SLP_VECTORIZE):
# numba's defaults (level 1 saves an eighth of the compile's CPU and costs the DEM kernel up to a
# tenth of its time, measured). numba's cache keys a compiled function on its signature and the
# CPU only, not on these: every process that compiles the kernels (the warm-up, a compile a run
# starts, a COLLIDE_JIT=1 test) sets them here, whatever its environment says, so the cache never
# mixes two settings.
CODE_GENERATION = {"NUMBA_OPT": "3", "NUMBA_LOOP_VECTORIZE": "1", "NUMBA_SLP_VECTORIZE": "0"}


def _same_code_generation() -> None:
    """Apply CODE_GENERATION before numba sets its code generator up (at the first compile or
    cache load). numba reads its settings again from the environment before each compile, so
    they are set there (this process's children inherit them) and read now."""
    from numba.core import config

    os.environ.update(CODE_GENERATION)
    config.reload_config()


def _one_signature(options: dict):
    """numba's `njit` with `options`, whose kernels are compiled for the types of their arguments
    only, never for the value of a constant one: numba types a constant argument in a call from
    another kernel as that value (`Literal[int](0)`, `Literal[bool](False)`), and compiles the
    callee again for each value and each mix of constant and variable arguments (52 extra
    compiles, 15 s of the compile's 181 s of CPU, measured). The optimiser still folds a
    constant into an inlined callee; a called one tests it at run time (kernel times unchanged,
    measured). Each kernel's dispatcher is made when first needed (`_Kernel`)."""
    from numba import njit
    from numba.core import types

    compile_for = njit(**options)
    part = bool(options.get("no_cpython_wrapper"))

    def make(function):
        dispatcher = compile_for(function)
        typed = dispatcher.get_call_template

        def get_call_template(args, kws):
            return typed(tuple(types.unliteral(a) for a in args), {k: types.unliteral(v) for k, v in kws.items()})

        dispatcher.get_call_template = get_call_template
        if part:
            _called_from_kernels_only(dispatcher)
        return dispatcher

    def decorate(function):
        return _Kernel(function, make, part)

    return decorate


class _Kernel:
    """A kernel whose numba dispatcher is made when something first needs it: numba typing a
    call to it from a kernel being compiled (it asks for `_numba_type_`), a call from Python, or
    any of the dispatcher's attributes. Making the engine's 230 dispatchers at import was a sixth
    of a compiled run's start (each inspects its function and tests its cache folder by writing
    a file), and a run that loads its kernels from the cache needs only the few it calls from
    Python; the others' code is in those kernels' machine code."""

    _making = threading.RLock()

    def __init__(self, function, make, part: bool) -> None:
        functools.update_wrapper(self, function)
        self.py_func = function
        self._make = make
        self._part = part
        self._dispatcher = None

    def dispatcher(self):
        """numba's dispatcher of this kernel (made once)."""
        if self._dispatcher is None:
            with self._making:
                if self._dispatcher is None:
                    self._dispatcher = self._make(self.py_func)
        return self._dispatcher

    def __getattr__(self, name: str):
        if name.startswith("__") or name in ("_dispatcher", "_make", "_part", "py_func"):
            raise AttributeError(name)  # probes (copy, pickle, inspect) make no dispatcher
        return getattr(self.dispatcher(), name)

    def __call__(self, *args, **kwargs):
        if self._part:  # a part has no entry from Python: it runs as Python (`_called_from_kernels_only`)
            return self.py_func(*args, **kwargs)
        return self.dispatcher()(*args, **kwargs)

    def __repr__(self) -> str:
        return f"<kernel {self.__module__}.{self.__qualname__}>"


def _called_from_kernels_only(dispatcher) -> None:
    """A kernel part compiled without numba's entry from Python (`no_cpython_wrapper`), whose
    machine code a call from Python would jump into with Python objects: kept for the kernels
    that call it, never registered for calls from Python, which run the Python function (the
    same code the interpreted engine runs; the tests call parts so)."""
    function = dispatcher.py_func

    def add_overload(compiled) -> None:
        dispatcher.overloads[tuple(compiled.signature.args)] = compiled

    def run_as_python(*args, **kwargs):
        return function  # numba's dispatcher calls what this returns with the call's arguments

    dispatcher.add_overload = add_overload
    dispatcher._compile_for_args = run_as_python


if tier.COMPILED:
    _import_numba_without_optional()
    from numba import config

    _set_up_target_to_compile_only()
    _load_environments_lazily()
    _type_arrays_without_numpy_ma()
    _parse_bitcode_when_linked()
    _compile_only_what_runs()
    _compile_entries_when_called()

    _same_code_generation()
    # The cache folder named after every kernel source (tier.cache_key): never a stale callee.
    config.CACHE_DIR = str(tier.cache_dir())
    # error_model="numpy": a division by zero gives inf or NaN (checked after each step) instead
    # of raising, which also keeps the compiled code smaller. No entry from C
    # (`no_cfunc_wrapper`): nothing takes a kernel's address.
    jit = _one_signature(dict(cache=True, error_model="numpy", nogil=True, no_cfunc_wrapper=True))
    # Pieces called per contact, per body or per substep, which allocate nothing (a contact
    # law's parts, a body's turn; the event engine's step with its kicks, friction solve,
    # geometry and mode values): inlined into the loops, and without reference counting
    # (`_nrt=False`, as numba's own sort and string helpers): a call each time, and the atomic
    # counts of each array passed, cost more than the physics (a quarter of the DEM step; the
    # event engine's steps 2-5 times, measured).
    # They are compiled without numba's entries from Python and from C (`no_cpython_wrapper`,
    # `no_cfunc_wrapper`): only kernels call them, and the entries, which unpack every array
    # passed, were most of a small part's code to optimise and compile (measured:
    # benchmarks/bench_compile.py).
    _part = dict(cache=True, error_model="numpy", nogil=True, _nrt=False, no_cpython_wrapper=True,
                 no_cfunc_wrapper=True)
    jit_inline = _one_signature(dict(_part, forceinline=True))
    # Large pieces of that kind called from several places (the event engine's step, friction
    # solve, hold, mode values, decision, settling): called, not copied into every call site,
    # which multiplied the machine code (the cache 32 MB) and the compile's time; still without
    # reference counting, which was most of the gain. Kernel times unchanged, measured.
    jit_call = _one_signature(_part)
    # Stages with one caller (the event engine's windows, islands, the step's event location)
    # allocate their work arrays, so they keep reference counting; called, not copied into
    # their caller (numba's `inline="always"` spent 10 s of CPU re-typing them inside
    # `simulate`; a call per window, island or step costs nothing measurable).
    jit_part = _one_signature(dict(cache=True, error_model="numpy", nogil=True, no_cpython_wrapper=True,
                                   no_cfunc_wrapper=True))
else:
    def jit(function):
        """Interpreted: the kernel as plain Python."""
        return function

    jit_inline = jit
    jit_call = jit
    jit_part = jit
