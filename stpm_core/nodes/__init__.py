"""Shader node graphs (plain data), their compiler to interpreter programs, and opcodes.

The interpreter itself is compiled code: :mod:`stpm_core.kernels.svm`.  Equations and the
node-by-node support table: docs/shader-nodes.md.
"""
from .graph import Link, Node, ShaderGraph, shader_lobes
from .compile import Program, compile_graph, SUPPORTED_NODES

__all__ = ["Link", "Node", "ShaderGraph", "shader_lobes", "Program", "compile_graph", "SUPPORTED_NODES"]
