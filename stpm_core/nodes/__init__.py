"""Shader node graphs (plain data), their compiler to interpreter programs, and opcodes.

The interpreter itself is compiled code: :mod:`stpm_core.kernels.svm`.  Equations and the
node-by-node support table: docs/shader-nodes.md.
"""
from .graph import Link, Node, ShaderGraph
from .compile import Program, compile_graph, SUPPORTED_NODES

__all__ = ["Link", "Node", "ShaderGraph", "Program", "compile_graph", "SUPPORTED_NODES"]
