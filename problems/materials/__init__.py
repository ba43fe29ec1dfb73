"""Constitutive models behind the :class:`problems.materials.base.Material` protocol."""

from problems.materials.base import DifferentiableMaterial, Material, MaterialUpdate
from problems.materials.elastic import LinearElastic

__all__ = ["Material", "DifferentiableMaterial", "MaterialUpdate", "LinearElastic"]
