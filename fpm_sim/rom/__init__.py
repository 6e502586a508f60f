"""Reduced-order modal models and the modal atlas (reduced models across poses)."""
